"""Numbers printed at the precision their uncertainty warrants: one helper for every report, plot and CLI line.

A measured value is printed to the decimal place of the second significant digit of its σ
(146.03 Hz beside σ 0.043 Hz, 146 Hz beside σ 12 Hz, never "146 Hz" beside σ 0.04 Hz); a value
without a σ gets :data:`DEFAULT_DIGITS` significant digits. Damping ratios stored as ln(ζ)
(the gap diagnosis's damping rows, docs/formats.md §5) are shown as ζ in %.
"""

from __future__ import annotations

import math

#: Significant digits of a σ (and so the last decimal shown of its value).
SIGMA_DIGITS = 2
#: Significant digits of a value printed without a σ.
DEFAULT_DIGITS = 4


def decimals(sigma: float, digits: int = SIGMA_DIGITS) -> int:
    """Decimal places that show ``sigma`` with ``digits`` significant digits (negative: round to tens, …);
    :data:`DEFAULT_DIGITS` − 1 for a σ that is zero, missing or not finite."""
    if sigma is None or not math.isfinite(sigma) or sigma <= 0:
        return DEFAULT_DIGITS - 1
    return digits - 1 - math.floor(math.log10(sigma))


#: Values at or beyond this magnitude (and non-zero ones below :data:`SCI_BELOW`) are written as m.mmme±XX.
SCI_FROM = 1e5
SCI_BELOW = 1e-3


def _sci_exponent(ax: float) -> int | None:
    """The power of ten a magnitude is written with, or ``None`` for plain digits."""
    return math.floor(math.log10(ax)) if ax >= SCI_FROM or 0 < ax < SCI_BELOW else None


def _fixed(x: float, places: int, exp: int | None | bool = True) -> str:
    """``x`` rounded to ``places`` decimals (negative: tens, hundreds …). ``exp``: ``True`` — scientific notation,
    with the same last digit, where plain digits would be long (≥ :data:`SCI_FROM` or < :data:`SCI_BELOW`);
    an int — that power of ten (numbers written side by side share one); ``None`` — plain digits."""
    if exp is True:
        exp = _sci_exponent(abs(x))
    if exp is not None:
        if x == 0:
            return "0"
        return f"{x / 10 ** exp:.{max(0, places + exp)}f}e{exp:+03d}"
    if places >= 0:
        return f"{x:.{places}f}"
    return f"{round(x, places):.0f}"


def fmt_value(value, sigma=None, digits: int = SIGMA_DIGITS) -> str:
    """``value`` to the decimal place its ``sigma`` warrants (``—`` for None; ``nan``/``inf`` as such); without a
    usable σ, :data:`DEFAULT_DIGITS` significant digits."""
    if value is None:
        return "—"
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    if sigma is None or not math.isfinite(float(sigma)) or float(sigma) <= 0:
        text = f"{value:#.{DEFAULT_DIGITS}g}"  # trailing zeros kept: they are significant digits
        return text[:-1] if text.endswith(".") else text
    return _fixed(value, decimals(float(sigma), digits))


def fmt_sigma(sigma, digits: int = SIGMA_DIGITS) -> str:
    """``sigma`` with ``digits`` significant digits, written to the same decimal place as :func:`fmt_value`."""
    if sigma is None:
        return "—"
    sigma = float(sigma)
    if not math.isfinite(sigma) or sigma <= 0:
        return f"{sigma:g}"
    return _fixed(sigma, decimals(sigma, digits))


def fmt_pm(value, sigma, unit: str = "", digits: int = SIGMA_DIGITS) -> str:
    """``"146.03 ± 0.04 Hz"``: value and σ at the σ's precision, then the unit (if any)."""
    text = f"{fmt_value(value, sigma, digits)} ± {fmt_sigma(sigma, digits)}"
    return f"{text} {unit}".rstrip() if unit else text


def fmt_interval(median, lo, hi, digits: int = SIGMA_DIGITS) -> tuple[str, str, str]:
    """A median and its interval, all three to one decimal place: that of the interval's narrower half-width
    (``digits`` significant digits; at least a tenth of the wider one), or finer where an end would otherwise
    keep fewer than ``digits`` significant digits (a skewed interval near zero: EI 0.251 (0.038 – 0.902)); at most 2 places finer."""
    median, lo, hi = float(median), float(lo), float(hi)
    h1, h2 = sorted((abs(median - lo), abs(hi - median)))
    half = max(h1, h2 / 10)  # a median at a bound of its interval (a parameter at its null) takes the other side
    if not (math.isfinite(half) and half > 0):
        return fmt_value(median), fmt_value(lo), fmt_value(hi)
    places = decimals(half, digits)
    ends = [decimals(abs(x), digits) for x in (lo, hi) if math.isfinite(x) and x != 0]
    places = min(max([places] + ends), places + 2)
    exp = _sci_exponent(max(abs(median), abs(lo), abs(hi)))  # one notation and power of ten for the three
    return _fixed(median, places, exp), _fixed(lo, places, exp), _fixed(hi, places, exp)


def damping_pct(ln_ratio) -> float:
    """ζ [%] of a damping row stored as ln(damping ratio) (docs/formats.md §5, ``baseline.unit``)."""
    return 100.0 * math.exp(float(ln_ratio))


def fmt_damping(ln_ratio, ln_sigma=None) -> str:
    """A damping row stored as ln(ζ) written as ζ in %: ``"1.23 %"``, or ``"1.23 % (± 4.1 %)"`` with its σ of
    ln ζ as a relative σ (σ_ζ/ζ ≈ σ of ln ζ)."""
    if ln_ratio is None or not math.isfinite(float(ln_ratio)):
        return "—"
    z = damping_pct(ln_ratio)
    if ln_sigma is None or not math.isfinite(float(ln_sigma)) or float(ln_sigma) <= 0:
        return f"{z:.3g} %"
    return f"{fmt_value(z, z * float(ln_sigma))} % (± {fmt_sigma(100 * float(ln_sigma))} %)"


__all__ = ["SIGMA_DIGITS", "DEFAULT_DIGITS", "decimals", "fmt_value", "fmt_sigma", "fmt_pm", "fmt_interval",
           "damping_pct", "fmt_damping"]
