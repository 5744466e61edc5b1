"""The least squares' models of the load disturbance, and their text form.

``constant``: the paper's d(t) = d0 (eq. 15). ``harmonic[:FREQ_HZ]``: d0 plus a
sinusoid, d(t) = d0 + d_sin sin(2 pi f t) + d_cos cos(2 pi f t), its frequency
given or estimated from the data. The command line (``--disturbance-model``)
and the app write a model this way; this module is light (no scipy), so that a
typo is refused before the estimator is loaded.

>>> parse_disturbance_model("harmonic:2")
('harmonic', 2.0)
>>> parse_disturbance_model("constant")
('constant', None)
>>> parse_disturbance_model("harmonic:x", name="--disturbance-model")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
eha_core._checks.FieldError: --disturbance-model = harmonic:x is not allowed: the frequency must be a number in ...
"""

from __future__ import annotations

import math

from .._checks import not_allowed

__all__ = ["DISTURBANCE_MODELS", "MAX_FREQ_HZ", "parse_disturbance_model"]

DISTURBANCE_MODELS = ("constant", "harmonic")
#: A harmonic's frequency must lie in (0, MAX_FREQ_HZ): the 1 kHz sensors' Nyquist frequency.
MAX_FREQ_HZ = 500.0


def parse_disturbance_model(text: str, name: str = "disturbance model") -> tuple[str, float | None]:
    """``(model, frequency or None)`` from ``constant`` or ``harmonic[:FREQ_HZ]``; ValueError otherwise.

    ``text`` is the model as typed, its frequency in Hz, in (0, :data:`MAX_FREQ_HZ`); a refusal
    names it ``name`` (an option such as ``--disturbance-model``).
    """
    model, sep, freq_text = str(text).strip().partition(":")
    usage = "use constant or harmonic[:FREQ_HZ]"
    typed = str(text)                     # written as given (not stripped)
    if model not in DISTURBANCE_MODELS or (model == "constant" and sep):
        raise not_allowed(name, text, usage, value_text=typed)
    if not freq_text.strip():
        if sep:
            raise not_allowed(name, text, f"give the frequency after ':' or leave it out; {usage}", value_text=typed)
        return model, None
    try:
        freq = float(freq_text)
    except ValueError:
        freq = float("nan")
    if not (math.isfinite(freq) and 0 < freq < MAX_FREQ_HZ):
        raise not_allowed(name, text, f"the frequency must be a number in (0, {MAX_FREQ_HZ:g}) Hz; {usage}",
                          value_text=typed)
    return model, freq
