"""What a closed-loop feedback page says: both answers' energy, where they part, and why.

A feedback item shows a wrong test answer beside Chip's best one. Showing two boards that
differ by a trail dot does not teach; this module computes, on the server (the page never
sees features or weights), the two energies, the first step where the routes part and one
sentence naming the feature whose count differs most in energy ("Your route moved out of a
yellow square twice more than Chip's: −6 energy."). Everything comes from the game table,
which was built with the domain's own `Instance.step`, and the domain's weights.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .texts import feature_phrase

MINUS = "\u2212"


def energy_text(x: float) -> str:
    """An energy figure as the page prints it: at most two decimals, a real minus sign."""
    v = round(float(x), 2)
    if v == 0:
        return "0"
    body = f"{abs(v):.2f}".rstrip("0").rstrip(".")
    return f"{MINUS}{body}" if v < 0 else f"+{body}"


def _walk(game: dict, actions: Sequence[str]) -> tuple[list[int], np.ndarray]:
    """State indices visited and feature counts of `actions` played from the start."""
    names = game["actions"]
    first = game["phi"][0]  # None when the start is terminal
    path, mu = [0], np.zeros(len(first[0]) if first else 0)
    for name in actions:
        s = path[-1]
        if game["terminal"][s]:
            raise ValueError(f"action {name!r} comes after the game ended")
        a = names.index(name)
        mu = mu + np.asarray(game["phi"][s][a], dtype=float)
        path.append(game["next"][s][a])
    return path, mu


def _times(n: int, more: bool) -> str:
    if more:
        return {1: "once more", 2: "twice more"}.get(n, f"{n} more times")
    return "one time fewer" if n == 1 else f"{n} fewer times"


def feedback_view(game: dict, weights: Sequence[float], feature_names: Sequence[str],
                  domain: str, answer: Sequence[str], best: Sequence[str]) -> dict:
    """The feedback page's content for `answer` against Chip's `best` action list.

    Returns ``answer_energy`` and ``best_energy`` (total reward of each), ``part_step``
    (how many states the two routes share before they part, so ``states[part_step - 1]``
    is where they part; None if they never do), ``part_cell`` (Chip's cell there),
    ``differences`` (per feature whose count differs: answer and best counts and the
    energy the difference costs) and ``sentence`` (one line naming the costliest one).
    """
    w = np.asarray(weights, dtype=float)
    path_a, mu_a = _walk(game, answer)
    path_b, mu_b = _walk(game, best)
    if mu_a.shape != w.shape or mu_b.shape != w.shape:
        raise ValueError(f"the game has {mu_a.size} features but {w.size} weights")
    part = next((t for t, (x, y) in enumerate(zip(path_a, path_b, strict=False)) if x != y),
                None)
    if part is None and len(path_a) != len(path_b):
        part = min(len(path_a), len(path_b))
    diffs = []
    for i, name in enumerate(feature_names):
        d = float(mu_a[i] - mu_b[i])
        if abs(d) > 1e-9:
            diffs.append({"feature": name, "answer": float(mu_a[i]), "best": float(mu_b[i]),
                          "energy": float(w[i] * d)})
    e_a, e_b = float(w @ mu_a), float(w @ mu_b)
    return {
        "answer_energy": e_a,
        "best_energy": e_b,
        "answer_energy_text": energy_text(e_a),
        "best_energy_text": energy_text(e_b),
        "part_step": part,
        "part_cell": (game["states"][path_a[part - 1]].get("agent")
                      if part is not None else None),
        "differences": diffs,
        "sentence": _sentence(domain, diffs, e_a - e_b),
    }


def _sentence(domain: str, diffs: list[dict], total: float) -> str:
    """One sentence from the feature whose different count cost the most energy."""
    costly = [d for d in diffs if d["energy"] < -1e-9]
    if not costly:  # equal energy (cannot be a wrong answer) or a gain elsewhere
        return (f"Your route's energy differs from Chip's by {energy_text(total)}.")
    top = min(costly, key=lambda d: d["energy"])
    n = round(abs(top["answer"] - top["best"]))
    more = top["answer"] > top["best"]
    phrase = feature_phrase(domain, top["feature"])
    out = f"Your route {phrase} {_times(n, more)} than Chip's: {energy_text(top['energy'])} energy"
    if len(costly) > 1 or abs(top["energy"] - total) > 1e-9:
        out += f" ({energy_text(total)} energy in all)"
    return out + "."


def feedback_for(study: dict, domain: str, game: dict, answer: Sequence[str],
                 best: Sequence[str]) -> dict:
    """`feedback_view` with the domain's weights and feature names from the study file."""
    info = study["domain_info"][domain]
    return feedback_view(game, info["weights"], info["feature_names"], domain, answer, best)
