"""Files a student downloads from tab 3's frequency domain: the estimated transfer function
(CSV, JSON) and the Bode diagram's curves (CSV).

They only write what the core computed. In an exercise the curves computed from
the hidden parameters (eq. 24's H(s)) are left out, as on the page.
"""

from __future__ import annotations

import csv
import io
import json
import zipfile

import numpy as np

from eha_core.identify._stats import Z95

__all__ = ["tf_estimate_rows", "tf_estimate_bytes", "bode_csv", "frequency_figures_zip"]


def _finite(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


def _no_nan(value):
    """``value`` with every non-finite float as None, numpy scalars as Python numbers."""
    if isinstance(value, dict):
        return {k: _no_nan(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_no_nan(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return _finite(value)
    if isinstance(value, np.integer):
        return int(value)
    return value


def tf_estimate_rows(estimate) -> list[dict]:
    """One row per coefficient of H(s) = (b0 s^m + ... + bm) / (s^n + a1 s^(n-1) + ... + an):
    its value, standard error and 95 % interval (``param_std`` is ordered ``[den[1:], num]``)."""
    n, m = estimate.n_poles, estimate.n_zeros
    names = [(f"a{k}", "den", n - k) for k in range(1, n + 1)] + [(f"b{k}", "num", m - k) for k in range(m + 1)]
    values = list(estimate.den[1:]) + list(estimate.num)
    std = list(estimate.param_std) if estimate.param_std is not None else [np.nan] * len(values)
    rows = []
    for (name, part, power), value, s in zip(names, values, std, strict=True):
        # r and x are both in m: the coefficient of s^power has the unit 1/s^(n - power)
        unit = "1" if n - power == 0 else f"1/s^{n - power}"
        rows.append({"coefficient": name, "of": part, "power_of_s": power, "unit": unit, "value": _finite(value),
                     "std_error": _finite(s), "ci95_low": _finite(value - Z95 * s),
                     "ci95_high": _finite(value + Z95 * s)})
    if estimate.input_offset is not None:
        s = estimate.input_offset_std if estimate.input_offset_std is not None else np.nan
        rows.append({"coefficient": "input_offset", "of": "input", "power_of_s": None, "unit": "m",
                     "value": _finite(estimate.input_offset), "std_error": _finite(s),
                     "ci95_low": _finite(estimate.input_offset - Z95 * s),
                     "ci95_high": _finite(estimate.input_offset + Z95 * s)})
    delay = getattr(estimate, "input_delay", 0.0) or 0.0
    if delay:
        s = getattr(estimate, "input_delay_std", None)
        s = np.nan if s is None else s
        rows.append({"coefficient": "input_delay_s", "of": "input", "power_of_s": None, "unit": "s",
                     "value": _finite(delay),
                     "std_error": _finite(s), "ci95_low": _finite(delay - Z95 * s),
                     "ci95_high": _finite(delay + Z95 * s)})
    return rows


def tf_estimate_bytes(estimate, kind: str, *, settings: dict | None = None, fits: dict | None = None) -> bytes:
    """The estimate as CSV (one row per coefficient) or JSON (the rows, the estimate's own fields,
    the settings it was made with and its fit percentages)."""
    rows = tf_estimate_rows(estimate)
    if kind == "json":
        out = {"estimate": _no_nan(estimate.to_dict()), "coefficients": rows, "settings": _no_nan(settings or {}),
               **{k: _finite(v) if v is not None else None for k, v in (fits or {}).items()}}
        # strict JSON (a NaN would break a JavaScript or MATLAB reader): a missing number is null
        return json.dumps(out, indent=1, allow_nan=False).encode()
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: "" if v is None else (f"{v:.10g}" if isinstance(v, float) else v) for k, v in row.items()})
    return buf.getvalue().encode()


def bode_csv(bode, *, theoretical: bool = True) -> bytes:
    """The Bode diagram's curves in long form: ``curve, w_rad_s, magnitude_db, phase_deg, lower_db, upper_db``.

    Curves: ``estimate``, ``linearised_eq24`` (when ``theoretical`` and known),
    and the data's points (``etfe`` or ``spectral``, the latter with its 95 % band).
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["curve", "w_rad_s", "magnitude_db", "phase_deg", "lower_db", "upper_db"])

    def put(name, ws, db, deg, lo=None, hi=None):
        for i, wv in enumerate(ws):
            w.writerow([name, f"{wv:.10g}", f"{db[i]:.10g}", f"{deg[i]:.10g}",
                        "" if lo is None else f"{lo[i]:.10g}", "" if hi is None else f"{hi[i]:.10g}"])

    put("estimate", bode.w, bode.estimate.magnitude_db, bode.estimate.phase_deg)
    if theoretical and bode.theoretical is not None:
        put("linearised_eq24", bode.w, bode.theoretical.magnitude_db, bode.theoretical.phase_deg)
    put("etfe" if bode.data_method == "etfe" else "spectral", np.asarray(bode.data_w),
        np.asarray(bode.data_magnitude_db), np.asarray(bode.data_phase_deg), bode.data_lower_db, bode.data_upper_db)
    return buf.getvalue().encode()


def frequency_figures_zip(fi, *, hidden: bool = False) -> bytes:
    """The data behind every figure of the frequency experiment, one CSV per figure and all of it
    in one .mat (variables named ``fig9_closed_loop_t``, ``fig12_bode_curves_estimate_db``, ...), zipped.

    ``hidden``: an exercise; eq. 24's curves (computed from the hidden values) are left out.
    """
    from eha_core.data import write_data

    d = fi.data
    tables = {"fig8_excitation": {"t": np.arange(fi.excitation.u.size) * fi.config.ts, "r": fi.excitation.u},
              "fig9_closed_loop": {"t": d.t, "r": d.r, "x": d.x, "u": d.u}}
    if fi.estimate_output is not None:
        fit = {"t": d.t, "x": d.x, "x_estimate": fi.estimate_output}
        if not hidden and fi.theoretical_comparison is not None:
            fit["x_eq24"] = fi.theoretical_comparison.y_hat
        tables["fig11_fit"] = fit
    if fi.validation is not None:
        vd = fi.validation_data
        tables["fig13_validation"] = {"t": vd.t, "r": vd.r, "x": vd.x, "x_estimate": fi.validation.y_hat}
    if fi.residuals is not None:
        ra = fi.residuals
        tables["residuals_autocorrelation"] = {"lag": ra.lags, "autocorrelation": ra.autocorrelation,
                                               "band_99": np.full(ra.lags.size, ra.confidence_bound)}
        tables["residuals_cross_correlation"] = {"lag": ra.cross_lags, "cross_correlation": ra.cross_correlation,
                                                 "band_99": np.full(ra.cross_lags.size, ra.confidence_bound)}
    if fi.bode is not None:
        b = fi.bode
        tables["fig12_bode_curves"] = {"w": b.w, "estimate_db": b.estimate.magnitude_db,
                                       "estimate_deg": b.estimate.phase_deg}
        if not hidden and b.theoretical is not None:
            tables["fig12_bode_curves"].update(eq24_db=b.theoretical.magnitude_db, eq24_deg=b.theoretical.phase_deg)
        points = {"w": b.data_w, "magnitude_db": b.data_magnitude_db, "phase_deg": b.data_phase_deg}
        if b.data_lower_db is not None:
            points.update(lower_db=b.data_lower_db, upper_db=b.data_upper_db)
        tables["fig12_bode_data_points"] = points
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, cols in tables.items():
            z.writestr(f"{name}.csv", write_data(cols, "csv", units="si"))
        z.writestr("figures.mat", write_data({f"{name}_{k}": v for name, cols in tables.items()
                                              for k, v in cols.items()}, "mat"))
    return buf.getvalue()
