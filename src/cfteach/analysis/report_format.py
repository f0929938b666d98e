"""How the report writes numbers and names: APA-style p and F, confidence intervals, means
with SDs, factor levels and model terms as a reader knows them.

Statistics are written the way the paper writes them ("F(2, 422) = 289.78, p < .001").
"""

from __future__ import annotations

from typing import Any

from cfteach.analysis.descriptives import CONDITION_LABELS

FACTOR_TITLES = {
    "counterfactual": ("H2", "counterfactual scaffolding"),
    "feature_scaffolding": ("H3", "feature scaffolding"),
    "condition": ("H4", "condition (4 levels)"),
}


LEVEL_NAMES: dict[str, dict[str, str]] = {
    "condition": CONDITION_LABELS,
    "counterfactual": {"0": "no counterfactual", "1": "counterfactual"},
    "feature_scaffolding": {"0": "no feature scaffolding", "1": "feature scaffolding"},
}


def fmt_p(p: float | None) -> str:
    """APA-style p: 'p < .001', 'p = .048', 'p > .999'."""
    if p is None:
        return "p = n/a"
    if p < 0.001:
        return "p < .001"
    if p > 0.999:
        return "p > .999"
    return "p = " + f"{p:.3f}".lstrip("0")


def fmt_df(x: float | None) -> str:
    if x is None:
        return "n/a"
    return str(int(round(x))) if abs(x - round(x)) < 1e-9 else f"{x:.2f}"


def fmt_num(x: float | None, digits: int = 2, lead: bool = True) -> str:
    """A number with `digits` decimals; without the leading zero if `lead` is False."""
    if x is None:
        return "n/a"
    s = f"{x:.{digits}f}"
    if not lead:
        s = s.replace("0.", ".", 1) if s.startswith(("0.", "-0.")) else s
    return s


def fmt_F(df1: float | None, df2: float | None, F: float | None, p: float | None) -> str:
    """'F(2, 422) = 289.78, p < .001'."""
    return f"F({fmt_df(df1)}, {fmt_df(df2)}) = {fmt_num(F)}, {fmt_p(p)}"


def level_name(factor: str, lvl: str) -> str:
    return LEVEL_NAMES.get(factor, {}).get(str(lvl), str(lvl))


def ci_text(ci: list | None, digits: int) -> str:
    if not ci or ci[0] is None:
        return ""
    return f"[{fmt_num(ci[0], digits, lead=False)}, {fmt_num(ci[1], digits, lead=False)}]"


def m_sd(m: dict[str, Any], digits: int = 2) -> str:
    if m["mean"] is None:
        return "n/a"
    sd = f" ({fmt_num(m['sd'], digits)})" if m["sd"] is not None else ""
    return fmt_num(m["mean"], digits) + sd


def glmm_term(term: str) -> str:
    """'counterfactual:difficulty[high]' -> 'CF × difficulty (high vs mean)'."""
    short = {
        "counterfactual": "CF",
        "feature_scaffolding": "FS",
        "domain_position": "domain position",
    }
    parts = []
    for part in term.split(":"):
        if "[" in part:
            name, lvl = part.rstrip("]").split("[")
            parts.append(f"{name} ({lvl} vs mean)")
        else:
            parts.append(short.get(part, part))
    return " × ".join(parts)
