"""What every row module shares: the registry (:func:`rows_for`), the
row type and the number formats of the table."""
import math
import os
from typing import Callable, Dict, List, Sequence, Tuple

#: the repository
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__))))
Row = Tuple[str, str, str]          # claim, script, result


class ReportError(ValueError):
    """A results directory or README the report cannot be made from."""


def fixed(x: float, digits: int = 2) -> str:
    return f'{x:.{digits}f}'


def f1(x: float) -> str:
    return fixed(x, 1)


def f2(x: float) -> str:
    return fixed(x, 2)


def f3(x: float) -> str:
    return fixed(x, 3)


def times(x: float, digits: int = None) -> str:
    """A ratio: one decimal below 10, none above, unless ``digits``."""
    if digits is None:
        digits = 1 if round(x, 1) < 10 else 0
    return f'{x:.{digits}f}x'


def seconds(x: float) -> str:
    """8.6, 162, 4650."""
    if round(x, 1) < 10:
        return f'{x:.1f}'
    if round(x) < 1000:
        return f'{x:.0f}'
    return sig(x, 3)


def sci(x: float) -> str:
    """One significant digit in short scientific notation: 4.7e-3 -> 5e-3."""
    text = f'{x:.0e}'
    mantissa, exponent = text.split('e')
    return f'{mantissa}e{int(exponent)}'


def sig(x: float, digits: int = 3) -> str:
    """``digits`` significant digits without scientific notation."""
    if x == 0:
        return '0'
    rounded = float(f'{x:.{digits}g}')
    decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(x)))))
    return f'{rounded:.{decimals}f}'


def pct(x: float, digits: int = 0) -> str:
    return f'{100 * x:.{digits}f}%'


def thousands(n: float, digits: int = 1) -> str:
    """50k, 2.5k, 1.2k, 2.0M."""
    if n >= 1e6:
        return f'{n / 1e6:.{digits}f}M'
    if n >= 1e3:
        text = f'{n / 1e3:.{digits}f}'
        if n >= 1e4:
            text = f'{n / 1e3:.0f}'
        return f'{text.rstrip("0").rstrip(".") if "." in text else text}k'
    return f'{n:.0f}'


def span(values: Sequence[float], fmt: Callable[[float], str],
         sep: str = '-') -> str:
    """'lo-hi' of the formatted extremes, or one value if they agree."""
    lo, hi = fmt(min(values)), fmt(max(values))
    return lo if lo == hi else f'{lo}{sep}{hi}'


def span_times(values: Sequence[float], digits: int = None) -> str:
    lo, hi = times(min(values), digits), times(max(values), digits)
    return lo if lo == hi else f'{lo[:-1]}-{hi}'


def span_pct(values: Sequence[float], digits: int = 0) -> str:
    lo, hi = pct(min(values), digits), pct(max(values), digits)
    return lo if lo == hi else f'{lo[:-1]}-{hi}'


def signed(x: float) -> str:
    return f'{x:+.2f}'


def strip_ext(name: str) -> str:
    return os.path.splitext(name)[0]


ROWS: Dict[str, Callable[[dict, dict], List[Row]]] = {}


# benchmarks that need hardware this machine may lack: their row says what
# is not verified while no JSON exists
UNVERIFIED: Dict[str, Row] = {}


def rows_for(name: str, unverified: Row = None):
    """Registers the row function of ``benchmarks/results/<name>.json``
    (the table lists the benchmarks in ``report_rows.ORDER``). With
    ``unverified`` (claim, script, result), a missing JSON gives that row
    instead of an error."""
    def register(function):
        ROWS[name] = function
        if unverified is not None:
            UNVERIFIED[name] = unverified
        return function
    return register


def pair(a: str, b: str, suffix: str = '') -> str:
    return f'{a}{suffix} each' if a == b else f'{a} vs {b}{suffix}'


def rank_correlation(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman's rho (Pearson of the ranks; ties broken by order)."""
    def ranks(values):
        order = sorted(range(len(values)), key=values.__getitem__)
        out = [0.0] * len(values)
        for rank, i in enumerate(order):
            out[i] = float(rank)
        return out
    a, b = ranks(list(x)), ranks(list(y))
    mean_a, mean_b = sum(a) / len(a), sum(b) / len(b)
    cov = sum((u - mean_a) * (v - mean_b) for u, v in zip(a, b))
    norm = math.sqrt(sum((u - mean_a) ** 2 for u in a)
                     * sum((v - mean_b) ** 2 for v in b))
    return cov / norm
