"""cfteach data in the RL ecosystem's formats: Minari datasets of the robot's demonstrations
and of people's test answers, replayable in the registered `cfteach/...` environments.

`episodes` builds the episodes (no extra dependency), `study_files` finds each study test's
instance and start, `minari_io` writes, opens and checks Minari datasets (`pip install
'cfteach[rl]'`). docs/ecosystem.md shows the commands and an IRL example.
"""

from cfteach.ecosystem.episodes import (
    Episode,
    answer_episodes,
    candidate_episodes,
    curriculum_episodes,
)
from cfteach.ecosystem.minari_io import (
    check_replay,
    dataset_exists,
    episode_metadata,
    load_dataset,
    write_dataset,
)

__all__ = ["Episode", "answer_episodes", "candidate_episodes", "check_replay",
           "curriculum_episodes", "dataset_exists", "episode_metadata", "load_dataset",
           "write_dataset"]
