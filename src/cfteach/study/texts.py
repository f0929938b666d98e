"""Participant-facing wording per domain (the original study's, see study-platform.md §1.3)."""

from __future__ import annotations

DOMAIN_TEXT: dict[str, dict] = {
    "delivery": {
        "title": "Delivery",
        "task": "Dropping off the circle at the purple square",
        "effects_word": "energy",
        "actions": [
            "Moving out of a yellow square (into yellow or white square)",
            "Moving through the green hexagon",
            "Any action that you take (e.g. moving right, picking up, etc)",
        ],
        "note": "",
        "keys": ["up", "down", "left", "right", "pickup", "dropoff"],
    },
    "tiles": {
        "title": "Tiles",
        "task": "Moving into the grey square",
        "effects_word": "energy",
        "actions": [
            "Moving out of a green circle (into any other space)",
            "Moving out of a light brown square (into any other space)",
            "Any action that you take (e.g. moving right)",
        ],
        "note": "",
        "keys": ["up", "down", "left", "right"],
    },
    "skateboard": {
        "title": "Skateboard",
        "task": "Moving into the grey square",
        "effects_word": "energy",
        "actions": [
            "Any action that you take with the orange rectangle "
            "(e.g. picking it up or moving with it)",
            "Moving out of a purple square (into purple or white square)",
            "Moving out of a white square (into purple or white square)",
        ],
        "note": "Note that you cannot move into a purple square while having picked up the "
                "orange rectangle.",
        "keys": ["up", "down", "left", "right", "pickup", "dropoff"],
    },
}


def domain_text(name: str, feature_names: tuple[str, ...] | list[str]) -> dict:
    """Wording for a domain; user domains get a generic table built from feature names."""
    if name in DOMAIN_TEXT:
        return DOMAIN_TEXT[name]
    return {
        "title": name.replace("_", " ").title(),
        "task": "Completing the game's task",
        "effects_word": "energy",
        "actions": [f.replace("_", " ") for f in feature_names],
        "note": "",
        "keys": ["up", "down", "left", "right", "pickup", "dropoff"],
    }


LIKERT = {
    "informativeness": {
        "question": "How informative were these demonstrations in understanding the best "
                    "strategy in this game?",
        "options": ["Not Informative", "Slightly Informative", "Moderately Informative",
                    "Very Informative", "Extremely Informative"],
    },
    "mental_effort": {
        "question": "How much mental effort was required to understand the best strategy in "
                    "this game?",
        "options": ["No Effort", "Slight Effort", "Moderate Effort", "Significant Effort",
                    "Extreme Effort"],
    },
    "confidence": {
        "question": "How confident are you that you minimized Chip's energy loss while "
                    "completing the task?",
        "options": ["Not Confident", "Slightly Confident", "Somewhat Confident",
                    "Very Confident", "Extremely Confident"],
    },
}

GENDERS = ["Male", "Female", "Non-binary", "Prefer not to disclose"]
EDUCATION = ["Less than high school", "High school", "Some college", "Bachelor's degree",
             "Master's degree", "Doctorate", "Prefer not to disclose"]

# What a route did, per feature, for the feedback page's sentence ("Your route <phrase>
# twice more than Chip's"). Keyed by feature name: the order of a domain's `actions` above
# is the original study's table order, not always its feature order (tiles).
FEATURE_PHRASES: dict[str, dict[str, str]] = {
    "delivery": {"toll": "moved out of a yellow square",
                 "hotswap": "went through the green hexagon",
                 "step": "took an action"},
    "tiles": {"A": "moved out of a light brown square",
              "B": "moved out of a green circle",
              "step": "took an action"},
    "skateboard": {"skateboard_step": "acted with the orange rectangle",
                   "path_step": "moved out of a purple square",
                   "base_step": "moved out of a white square"},
}


def feature_phrase(domain: str, feature: str) -> str:
    """What a route did when `feature` counted; a user domain's feature is named plainly."""
    known = FEATURE_PHRASES.get(domain, {}).get(feature)
    return known or f"counted \u201c{feature.replace('_', ' ')}\u201d"


NUMBER_WORDS = ["no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine",
                "ten", "eleven", "twelve"]


def count_words(n: int) -> str:
    """A small count in words ("three"), larger ones in digits."""
    return NUMBER_WORDS[n] if 0 <= n < len(NUMBER_WORDS) else str(n)


def design_facts(study: dict) -> dict:
    """What the page's wording needs to know of the study's design (so a one-game study is
    never told about "three main games"): the number of games, tests per game (None if
    they differ) and an estimate of the minutes it takes (the original's 25 for 3 games)."""
    domains = list(study["domains"])
    n_tests = {len(study["tests"][d][0]) for d in domains if study["tests"].get(d)}
    return {"n_games": len(domains), "n_tests": n_tests.pop() if len(n_tests) == 1 else None,
            "minutes": 4 + 7 * len(domains)}
