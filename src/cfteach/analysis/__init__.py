"""Statistics, figures and report of a user study, from the study platform's CSV export.

`analyze(export_dir, out_dir)` runs everything; the pieces are `load_export` (io),
`apply_exclusions` (exclusions), `build_frames` (aggregate), `stats`, `figures`, `report`,
and `synthetic.generate` for simulated exports with planted effects.
"""

from cfteach.analysis.errors import ExportError
from cfteach.analysis.exclusions import ExclusionConfig, apply_exclusions
from cfteach.analysis.io import StudyExport, load_export, write_export
from cfteach.analysis.pipeline import AnalysisConfig, analyze, compute_results
from cfteach.analysis.synthetic import SyntheticConfig, generate

__all__ = [
    "AnalysisConfig",
    "ExclusionConfig",
    "ExportError",
    "StudyExport",
    "SyntheticConfig",
    "analyze",
    "apply_exclusions",
    "compute_results",
    "generate",
    "load_export",
    "write_export",
]
