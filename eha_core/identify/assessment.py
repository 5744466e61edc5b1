"""Residual analysis with a verdict: what the correlations say, in one sentence each.

:func:`~eha_core.identify.validate.residual_analysis` gives the
autocorrelation of the residuals (lags 1..L; lag 0 is 1 by definition) and
their cross-correlation with the input (lags -L..L), with the 99 % band
``+-2.58/sqrt(N)``. For residuals that are white and independent of the
input, each normalised correlation is close to ``N(0, 1/N)``, so each lag
falls outside the band with probability 1 % **by chance**; MATLAB's ``resid``
draws the band and leaves the reading to the eye. Asking for every lag to be
inside rejects a correct model too often: with the 51 lags of the
cross-correlation at ``L = 25``, ``1 - 0.99^51 = 40 %`` of correct models
would fail.

The pass rule here
------------------
The lags of white residuals are nearly independent, so the number of lags
outside the band is about binomial, ``Binomial(n_lags, 0.01)``. A test
passes when

1. at most ``k`` lags are outside, ``k`` the smallest count that chance
   exceeds with probability at most ``false_alarm`` (default 5 %): ``k = 1``
   of 25 autocorrelation lags (chance exceeds it with probability 2.6 %),
   ``k = 2`` of 51 cross-correlation lags (1.5 %); and
2. no lag lies far outside: beyond ``z / sqrt(N)`` with ``z`` the
   two-sided normal quantile of probability ``false_alarm / (2 n_lags)``
   (Bonferroni with half the budget: 3.29 for 25 lags, 3.49 for 51 at 5 %).
   One large spike (a missed delay, say) is structure, not chance.

On white residuals and a white input (3000 trials each at N = 1000 and
4000) the rule failed the whiteness test in 4.8 % of the trials and the
independence test in 3-4 %. With a coloured input the cross-correlation's
lags are correlated with one another (exceedances come in clusters) and
correct models fail more often; the sentence gives the counts, so the reader
can judge.

Only numpy and scipy are imported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.special

from .._checks import not_allowed

__all__ = ["CorrelationVerdict", "ResidualAssessment", "assess_residuals", "chance_allowance"]

#: Probability of the 99 % band being left by chance at one lag.
BAND_PROBABILITY = 0.01


@dataclass(frozen=True)
class CorrelationVerdict:
    """The verdict of one correlation test.

    Attributes
    ----------
    test : str
        ``"whiteness"`` (autocorrelation of the residuals) or
        ``"independence"`` (cross-correlation with the input).
    title : str
        What was tested, for a heading.
    passed : bool
    n_outside : int
        Lags outside the 99 % band.
    n_lags : int
        Lags tested (lag 0 of the autocorrelation is not).
    allowed : int
        Lags that may be outside by chance (see the module docstring).
    worst_lag : int
        The lag of the largest ``|correlation|``.
    worst_value : float
        The correlation there.
    bound : float
        Half-width of the 99 % band.
    far_bound : float
        Half-width beyond which a single lag fails the test.
    sentence : str
        The verdict and what it means, generated from the numbers.
    """

    test: str
    title: str
    passed: bool
    n_outside: int
    n_lags: int
    allowed: int
    worst_lag: int
    worst_value: float
    bound: float
    far_bound: float
    sentence: str


@dataclass(frozen=True)
class ResidualAssessment:
    """Both verdicts of a residual analysis.

    ``whiteness`` and ``independence`` are :class:`CorrelationVerdict`;
    ``passed`` is True when both pass; ``false_alarm`` the rule's setting;
    ``n_samples`` the residuals' length.
    """

    whiteness: CorrelationVerdict
    independence: CorrelationVerdict
    passed: bool
    false_alarm: float
    n_samples: int

    @property
    def verdicts(self) -> tuple[CorrelationVerdict, CorrelationVerdict]:
        """Cross-correlation first: it speaks of the dynamics, the model's main job."""
        return (self.independence, self.whiteness)

    @property
    def sentences(self) -> tuple[str, str]:
        return tuple(v.sentence for v in self.verdicts)


def chance_allowance(n_lags: int, false_alarm: float = 0.05, p: float = BAND_PROBABILITY) -> int:
    """Lags that may lie outside the band by chance.

    The smallest ``k`` with ``P(Binomial(n_lags, p) > k) <= false_alarm``.

    Parameters
    ----------
    n_lags : int
        The lags tested.
    false_alarm : float
        The largest probability that a white, independent residual fails the test.
    p : float
        The probability that one lag lies outside the band by chance (0.01 for the 99 % band).

    Examples
    --------
    >>> chance_allowance(25), chance_allowance(51)
    (1, 2)
    """
    k, cdf = 0, (1.0 - p) ** n_lags
    while 1.0 - cdf > false_alarm:
        k += 1
        cdf += math.comb(n_lags, k) * p**k * (1.0 - p) ** (n_lags - k)
    return k


def _lags_phrase(n: int, n_lags: int, allowed: int, inside: bool) -> str:
    if n == 0:
        return f"0 of {n_lags} lags outside the 99 % band"
    tail = f", within the {allowed} that chance allows" if inside else ""
    return f"{n} of {n_lags} lag{'s' if n_lags != 1 else ''} outside the 99 % band{tail}"


def _verdict(test: str, lags: np.ndarray, values: np.ndarray, bound: float, n_samples: int,
             false_alarm: float, remedy: str = "try more poles or a delay") -> CorrelationVerdict:
    n_lags = int(values.size)
    outside = np.abs(values) > bound
    n_out = int(outside.sum())
    allowed = chance_allowance(n_lags, false_alarm)
    z_far = float(-scipy.special.ndtri(false_alarm / (4.0 * n_lags)))
    far_bound = z_far / math.sqrt(n_samples)
    i_worst = int(np.argmax(np.abs(values)))
    worst_lag, worst_value = int(lags[i_worst]), float(values[i_worst])
    far = abs(worst_value) > far_bound
    passed = n_out <= allowed and not far
    where = f"largest at lag {worst_lag}"
    if far and n_out <= allowed:
        where += f", {abs(worst_value):.3g} against a band of +-{bound:.3g}: too far out to be chance"
    counts = _lags_phrase(n_out, n_lags, allowed, passed)
    if test == "independence":
        title = "Cross-correlation of the residuals with the input"
        if passed:
            sentence = (f"The residuals are uncorrelated with the input ({counts}): "
                        "the model explains what the input does.")
        elif worst_lag < 0:
            sentence = (f"The residuals are correlated with the input ({counts}, {where}, a negative lag: the "
                        "input follows the residuals): a sign of feedback from the output to the input "
                        "(closed-loop data), or of a model that responds before its input.")
        else:
            sentence = (f"The residuals are correlated with the input ({counts}, {where}): the model misses "
                        f"dynamics — {remedy}.")
    else:
        title = "Autocorrelation of the residuals"
        if passed:
            sentence = (f"The residuals are white ({counts}, lag 0 excluded): the noise model is adequate "
                        "and nothing predictable is left in them.")
        else:
            sentence = (f"The residuals are correlated with themselves ({counts}, {where}): coloured noise or "
                        "unmodelled dynamics — if the cross-correlation passes, the dynamics are fine and only "
                        "the noise is coloured (an output-error model does not model it).")
    return CorrelationVerdict(test=test, title=title, passed=bool(passed), n_outside=n_out, n_lags=n_lags,
                              allowed=allowed, worst_lag=worst_lag, worst_value=worst_value, bound=float(bound),
                              far_bound=float(far_bound), sentence=sentence)


def assess_residuals(analysis, *, false_alarm=0.05, remedy: str = "try more poles or a delay") -> ResidualAssessment:
    """Verdicts of the whiteness and independence tests of a residual analysis.

    Parameters
    ----------
    analysis : ResidualAnalysis
        From :func:`eha_core.identify.validate.residual_analysis`.
    remedy : str
        What the sentence advises when the residuals follow the input (the model misses dynamics):
        for a transfer function, more poles or a delay.
    false_alarm : float
        The chance, per test, of failing white residuals that the rule
        accepts (default 0.05): the count part is set at it, the far-lag part
        at half of it (see the module docstring).

    Returns
    -------
    ResidualAssessment

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.validate import residual_analysis
    >>> rng = np.random.default_rng(0)
    >>> a = assess_residuals(residual_analysis(rng.standard_normal(2000), rng.standard_normal(2000)))
    >>> a.passed
    True
    >>> print(a.independence.sentence)  # doctest: +NORMALIZE_WHITESPACE
    The residuals are uncorrelated with the input (0 of 51 lags outside the 99 % band):
    the model explains what the input does.
    """
    for attr in ("lags", "autocorrelation", "cross_lags", "cross_correlation", "confidence_bound", "n_samples"):
        if not hasattr(analysis, attr):
            raise not_allowed("analysis", analysis, "must be a ResidualAnalysis (from residual_analysis)")
    try:
        false_alarm = float(false_alarm)
    except (TypeError, ValueError):
        false_alarm = float("nan")
    if not 0.0 < false_alarm < 0.5:
        raise not_allowed("false_alarm", false_alarm, "must be a probability in (0, 0.5), e.g. 0.05")
    n = int(analysis.n_samples)
    bound = float(analysis.confidence_bound)
    lags = np.asarray(analysis.lags)
    auto = np.asarray(analysis.autocorrelation, dtype=float)
    keep = lags != 0   # lag 0 of an autocorrelation is 1 by definition
    whiteness = _verdict("whiteness", lags[keep], auto[keep], bound, n, false_alarm)
    independence = _verdict("independence", np.asarray(analysis.cross_lags),
                            np.asarray(analysis.cross_correlation, dtype=float), bound, n, false_alarm, remedy)
    return ResidualAssessment(whiteness=whiteness, independence=independence,
                              passed=whiteness.passed and independence.passed, false_alarm=false_alarm,
                              n_samples=n)
