"""Text alternatives of the figures: what each one plots, read from its Bokeh models.

A Bokeh figure is a canvas, which a screen reader cannot read. Each figure's element
carries ``role="figure"`` and an ``aria-label`` that says what it plots: its title,
its axes with their units, and each trace with its name (the legend's label, the
renderer's ``name`` or a ``label``/``name`` column of a multi-line) and the range of
its data, the numbers a sighted student reads off the axes. ``role="figure"`` and not
``"img"``: a figure's toolbar buttons stay reachable (an image's children are hidden
from assistive technology).

The text is computed from the figure's data sources, so it says what is drawn, and
written again after every ``update()`` of the figure classes (:class:`Described`):
figures show new results by replacing their data in place, in the same message as the
data (an unchanged text is not sent again).
"""

from __future__ import annotations

import functools

import numpy as np
from bokeh.models import (
    GlyphRenderer,
    Legend,
    Line,
    MultiLine,
    Patches,
    Plot,
    Quad,
    Scatter,
    Segment,
    Step,
    VArea,
)

__all__ = ["describe_figure", "set_description", "Described", "MAX_TRACES"]

#: Traces named in one figure's text at most (the model board may overlay a dozen models).
MAX_TRACES = 12
#: Marked points listed one by one up to this many (more are summed up by their ranges).
MAX_POINTS_LISTED = 8


def _num(value: float) -> str:
    return f"{value:.4g}"


def _field(spec) -> str | None:
    """The column a glyph property reads, or None for a fixed value."""
    if isinstance(spec, str):
        return spec
    field = getattr(spec, "field", None)
    if isinstance(field, str):
        return field
    if isinstance(spec, dict) and isinstance(spec.get("field"), str):
        return spec["field"]
    return None


def _finite(values) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        return np.asarray([], dtype=float)
    return a[np.isfinite(a)]


def _span(values) -> tuple[float, float] | None:
    a = _finite(values)
    return (float(a.min()), float(a.max())) if a.size else None


def _range_text(label: str, values) -> str:
    span = _span(values)
    if span is None:
        return ""
    lo, hi = span
    return f"{label} {_num(lo)}" if lo == hi else f"{label} from {_num(lo)} to {_num(hi)}"


def _axis_label(axes, fallback: str) -> str:
    for axis in axes:
        if getattr(axis, "axis_label", None):
            return str(axis.axis_label)
    return fallback


def _legend_names(fig: Plot) -> dict:
    """The label of each renderer that a visible legend entry names."""
    names = {}
    for legend in (m for side in (fig.above, fig.center, fig.below, fig.left, fig.right) for m in side
                   if isinstance(m, Legend)):
        for item in legend.items:
            label = item.label
            text = label.get("value") if isinstance(label, dict) else getattr(label, "value", label)
            if item.visible and isinstance(text, str) and text:
                for r in item.renderers:
                    names.setdefault(r.id, text)
    return names


def _column(data: dict, spec):
    name = _field(spec)
    return data.get(name) if name is not None else None


def _traces(r: GlyphRenderer, name: str, x_label: str, y_label: str) -> list[str]:
    """One sentence per trace the renderer draws (none when it draws nothing)."""
    glyph, data = r.glyph, r.data_source.data if hasattr(r.data_source, "data") else {}
    if isinstance(glyph, (Line, Step, Scatter)):
        x, y = _column(data, glyph.x), _column(data, glyph.y)
        if x is None or y is None:
            return []
        return [_points(name, x, y) if isinstance(glyph, Scatter) and 0 < len(_finite(y)) <= MAX_POINTS_LISTED
                else _sentence(name, x, y, x_label, y_label)]
    if isinstance(glyph, (MultiLine, Patches)):
        xs, ys = _column(data, glyph.xs), _column(data, glyph.ys)
        if xs is None or ys is None:
            return []
        labels = data.get("label", data.get("name"))
        labels = [] if labels is None else list(labels)
        out = []
        for i, (x, y) in enumerate(zip(xs, ys, strict=False)):
            own = labels[i] if i < len(labels) and labels[i] else f"{name} {i + 1}"
            out.append(_sentence(own, x, y, x_label, y_label, shaded=isinstance(glyph, Patches)))
        return out
    if isinstance(glyph, Segment):
        x, y = _column(data, glyph.x1), _column(data, glyph.y1)
        return [_sentence(name, x, y, x_label, y_label)] if x is not None and y is not None else []
    if isinstance(glyph, VArea):
        x = _column(data, glyph.x)
        lo, hi = _column(data, glyph.y1), _column(data, glyph.y2)
        if x is None or lo is None or hi is None:
            return []
        return [_sentence(name, x, np.concatenate([_finite(lo), _finite(hi)]), x_label, y_label, shaded=True)]
    if isinstance(glyph, Quad):
        left, right, top = (_column(data, s) for s in (glyph.left, glyph.right, glyph.top))
        if left is None or right is None or top is None or not _finite(top).any():
            return []
        lo, hi = _span(left), _span(right)
        peak = _span(top)
        if lo is None or hi is None or peak is None:
            return []
        return [f"{name}: {len(_finite(top))} bars over {x_label} from {_num(lo[0])} to {_num(hi[1])}, the highest "
                f"{_num(peak[1])} {y_label}."]
    return []


def _points(name: str, x, y) -> str:
    """A few marked points, each at its coordinates (poles and zeros, a flagged root)."""
    try:
        pairs = [(float(a), float(b)) for a, b in zip(x, y, strict=True)]
    except (TypeError, ValueError):
        return ""
    pairs = [(a, b) for a, b in pairs if np.isfinite(a) and np.isfinite(b)]
    at = ", ".join(f"({_num(a)}, {_num(b)})" for a, b in pairs)
    return f"{name}: {len(pairs)} {'point' if len(pairs) == 1 else 'points'} at {at}." if pairs else ""


def _sentence(name: str, x, y, x_label: str, y_label: str, *, shaded: bool = False) -> str:
    xs, ys = _finite(x), _finite(y)
    if not ys.size:
        return ""
    what = "shaded region" if shaded else ("point" if ys.size == 1 else "points")
    count = "" if shaded else f"{ys.size} {what}, "
    parts = [p for p in (_range_text(x_label, xs), _range_text(y_label, ys)) if p]
    return f"{name}: {count}{'; '.join(parts)}."


def describe_figure(fig: Plot) -> str:
    """What ``fig`` plots, in one paragraph: its title, its axes and each drawn trace's range.

    >>> from bokeh.models import ColumnDataSource
    >>> from bokeh.plotting import figure
    >>> fig = figure(title="Position", x_axis_label="t [s]", y_axis_label="x [mm]")
    >>> r = fig.line("t", "x", source=ColumnDataSource({"t": [0.0, 1.0, 2.0], "x": [-1.5, 0.0, 3.25]}),
    ...              name="measured")
    >>> describe_figure(fig)
    'Figure: Position. x [mm] against t [s]. measured: 3 points, t [s] from 0 to 2; x [mm] from -1.5 to 3.25.'
    """
    # (a figure without a title of its own, below another, may carry a name: "Bode diagram, phase")
    title = fig.title.text if fig.title is not None and fig.title.text else (fig.name or "")
    x_label = _axis_label(fig.below + fig.above, "x")
    y_label = _axis_label(fig.left + fig.right, "y")
    legend = _legend_names(fig)
    sentences = []
    # the curves and points first, the shaded bands and regions around them after
    drawn = [r for r in fig.renderers if isinstance(r, GlyphRenderer) and r.visible]
    for r in sorted(drawn, key=lambda r: isinstance(r.glyph, (Patches, VArea))):
        name = legend.get(r.id) or r.name or _field(getattr(r.glyph, "y", None)) or type(r.glyph).__name__
        # two glyphs of one trace (a stem and its marker) say the same: once
        sentences += [s for s in _traces(r, name, x_label, y_label) if s and s not in sentences]
    head = f"Figure: {title}. " if title else "Figure. "
    head += f"{y_label} against {x_label}."
    if not sentences:
        return f"{head} Nothing drawn yet."
    more = len(sentences) - MAX_TRACES
    body = " ".join(sentences[:MAX_TRACES]) + (f" And {more} more." if more > 0 else "")
    return f"{head} {body}"


def set_description(fig: Plot) -> None:
    """Write ``fig``'s text alternative on its element (only when it changed: nothing is sent otherwise)."""
    attributes = {"role": "figure", "aria-label": describe_figure(fig)}
    if dict(fig.html_attributes) != attributes:
        fig.html_attributes = attributes


class Described:
    """Base of the figure classes: the text of each of their figures is written after ``__init__`` and
    after every ``update()``, from the data then drawn (see the module docstring).

    The figures are found among the instance's attributes: a Bokeh figure, or a list, tuple or dict
    of them.
    """

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for method in ("__init__", "update"):
            fn = cls.__dict__.get(method)
            if fn is not None:
                setattr(cls, method, _then_described(fn))

    def described_figures(self) -> list[Plot]:
        found = []
        for value in vars(self).values():
            if isinstance(value, dict):
                value = list(value.values())
            items = value if isinstance(value, (list, tuple)) else (value,)
            found += [v for v in items if isinstance(v, Plot) and all(v is not f for f in found)]
        return found

    def describe(self) -> None:
        for fig in self.described_figures():
            set_description(fig)


def _then_described(fn):
    @functools.wraps(fn)
    def described(self, *args, **kwargs):
        out = fn(self, *args, **kwargs)
        self.describe()
        return out
    return described
