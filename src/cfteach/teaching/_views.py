"""The two views of a state that the authors' visual dissimilarity compares (docs/profiles.md,
difference 7): both the scalar measures (`visual`) and their batched forms (`visual_arrays`)
read them."""

from __future__ import annotations

from cfteach.domains import Instance, State


def _hash_view(inst: Instance, state: State) -> list[int]:
    return inst.state_hash_digits(state)


def _data_view(inst: Instance, state: State) -> list[int]:
    if not inst.has_cargo_slot and not len(inst.consumables_present):
        return inst.state_hash_digits(state)
    return inst.state_attribute_tuple(state)
