"""The verdict every job ends with: one shape for every command, its exit code, and the 99 % z.

A verdict says how far a result can be used (docs/architecture.md, "One verdict"):

- ``trusted``: estimated and every check passed (exit 0);
- ``not trusted``: estimated, but a check failed; the reasons say which (exit 4);
- ``not determined``: the data do not determine the answer; no number is claimed (exit 3).

Every result.json carries it as its ``verdict`` block (:meth:`Verdict.to_dict`); `rscalib batch`
reads that block back (:meth:`Verdict.from_dict`) instead of decoding each command's fields, and the
files for other tools carry only values whose verdict stands behind them (:attr:`Verdict.claims`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

# Two-sided 99 % of a normal distribution: bounds_99 = value +- Z_99 sigma.
Z_99 = 2.5758293035489004

TRUSTED, NOT_TRUSTED, NOT_DETERMINED = "trusted", "not trusted", "not determined"
STATUSES = (TRUSTED, NOT_TRUSTED, NOT_DETERMINED)
EXIT_CODES = {TRUSTED: 0, NOT_DETERMINED: 3, NOT_TRUSTED: 4}


def _finite(value) -> Optional[float]:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


@dataclass(frozen=True)
class Verdict:
    """How far a result can be used, with the headline quantity it is about.

    quantity: the headline number's name with its unit (``line_delay_s``, ``f_px``, ``fx_px``);
    value, std, bounds_99: that number with its standard deviation and 99 % bounds (None where not
    claimed: a ``not determined`` verdict claims no value, only the bounds the data allow, if any)."""

    status: str
    headline: str
    reasons: tuple = ()
    quantity: str = ""
    value: Optional[float] = None
    std: Optional[float] = None
    bounds_99: Optional[tuple] = None
    unit: str = ""
    caveats: tuple = field(default=())   # said with a trusted verdict, without changing it

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"unknown verdict status {self.status!r} ({', '.join(STATUSES)})")
        object.__setattr__(self, "reasons", tuple(self.reasons))
        object.__setattr__(self, "caveats", tuple(self.caveats))
        if self.status == NOT_DETERMINED:   # no number is claimed
            object.__setattr__(self, "value", None)
            object.__setattr__(self, "std", None)

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.status]

    @property
    def trusted(self) -> bool:
        return self.status == TRUSTED

    @property
    def claims(self) -> bool:
        """True when the verdict stands behind a number (trusted or not trusted, not undetermined):
        only then may it go into a file for another tool."""
        return self.status != NOT_DETERMINED

    def to_dict(self) -> dict:
        """The result.json ``verdict`` block."""
        bounds = None if self.bounds_99 is None else [_finite(b) for b in self.bounds_99]
        return {"status": self.status, "trust": self.trusted, "exit_code": self.exit_code,
                "headline": self.headline, "reasons": list(self.reasons), "caveats": list(self.caveats),
                "quantity": self.quantity, "unit": self.unit, "value": _finite(self.value),
                "std": _finite(self.std), "bounds_99": bounds}

    @classmethod
    def from_dict(cls, block: dict) -> Verdict:
        """A verdict read back from a result.json ``verdict`` block (ValueError when it is not one)."""
        if not isinstance(block, dict) or block.get("status") not in STATUSES:
            raise ValueError("not a verdict block")
        bounds = block.get("bounds_99")
        return cls(status=block["status"], headline=str(block.get("headline", "")),
                   reasons=tuple(str(r) for r in block.get("reasons") or ()),
                   quantity=str(block.get("quantity", "")), value=_finite(block.get("value")),
                   std=_finite(block.get("std")), unit=str(block.get("unit", "")),
                   bounds_99=None if not isinstance(bounds, (list, tuple)) or len(bounds) != 2 else tuple(bounds),
                   caveats=tuple(str(c) for c in block.get("caveats") or ()))


def std_from_bounds_99(bounds: Optional[tuple]) -> Optional[float]:
    """The standard deviation that 99 % bounds of a normal stand for (None without finite bounds)."""
    if bounds is None or len(bounds) != 2:
        return None
    lo, hi = (_finite(b) for b in bounds)
    if lo is None or hi is None:
        return None
    return (hi - lo) / (2.0 * Z_99)
