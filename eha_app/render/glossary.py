"""One-line explanations of the words a student meets for the first time.

:func:`term` writes a word with its explanation as a tooltip (an ``<abbr>``
with a dotted underline), wherever the word appears in the page.

>>> term("fit", "fit 96.5 %")[:40]
'<abbr class="eha-term" title="100 (1 − ‖'
>>> term("ZOH").endswith('>ZOH</abbr>')
True
"""

from __future__ import annotations

import html

__all__ = ["GLOSSARY", "term"]

GLOSSARY = {
    "SRIVC": "simplified refined instrumental variables for continuous-time models: it filters the data and "
             "re-estimates the transfer function until it settles, using a simulated output as instrument so "
             "that noise does not bias the estimate",
    "output error": "the estimate that makes the model's simulated output closest to the measured one "
                    "(least squares on the simulation error)",
    "ETFE": "empirical transfer-function estimate: the ratio of the output's and the input's discrete Fourier "
            "transforms at the excited frequencies; valid for periodic data over whole periods",
    "spectral estimate": "a smoothed estimate of the frequency response from the data's correlation functions "
                         "(Blackman-Tukey with a Hann window, like MATLAB's spa): valid for any excitation",
    "ZOH": "zero-order hold: the controller's output is held constant between two samples",
    "Newey-West": "standard errors that allow for residuals correlated over a few samples (the prefilter "
                  "correlates them); textbook intervals assume they are not and come out too narrow",
    "regressor": "a measured or filtered signal that multiplies an unknown parameter in the equation the least "
                 "squares solve",
    "poles": "the roots of the denominator: each gives a mode e^(pt) of the response; the model is stable when "
             "all lie left of the imaginary axis",
    "zeros": "the roots of the numerator; n_zeros must be below n_poles (a strictly proper model)",
    "fit": "100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖) %, as MATLAB's compare computes it, with the model's initial "
           "state and a constant input offset fitted (unless its label says otherwise): 100 % is a perfect match, "
           "0 % no better than a constant",
    "idinput": "the excitation generator of MATLAB's System Identification Toolbox: random Gaussian (rgs), "
               "random binary (rbs), pseudo-random binary (prbs) or a sum of sinusoids (sine)",
    "initial condition": "the model's state at t = 0: zero, or estimated together with the model",
    "input offset": "a constant added to the input, estimated with the model: here it absorbs the valve's "
                    "different gains for u ≥ 0 and u < 0",
}


def term(word: str, shown: str | None = None) -> str:
    """``shown`` (default ``word``) with the glossary's explanation of ``word`` as its tooltip."""
    title = html.escape(GLOSSARY[word], quote=True)
    return f'<abbr class="eha-term" title="{title}">{html.escape(shown or word)}</abbr>'
