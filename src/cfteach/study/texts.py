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
