"""Evidence on real data: descriptor modes, the paper's learners, protocols and the report.

Modules: :mod:`.sampling` (trial ranges, crop rule, seeded windows),
:mod:`.bank` (feature bank and named descriptor modes), :mod:`.classifiers`
(SVM with the paper's C grid, PA-I curve, GMM/NMI), :mod:`.experiments`
(one split, trial CV) and :mod:`.report` (``tactile report``).
"""

import importlib

__all__ = [
    "C_GRID", "C_GRID_TEXT", "SCALINGS", "fit_svm", "gmm_nmi", "pa_curve",
    "CLASSIFIERS", "EvalConfig", "evaluate", "trial_cv",
    "DESCRIPTOR_MODES", "compute_bank", "select_features",
    "common_length_frames", "draw_windows", "parse_trials",
]

# Names are imported on first use (PEP 562): scikit-learn takes seconds to
# import, and `tactile --help` or an unrelated subcommand should not pay it.
_HOME = {
    **dict.fromkeys(("C_GRID", "C_GRID_TEXT", "SCALINGS", "fit_svm", "gmm_nmi", "pa_curve"), "classifiers"),
    **dict.fromkeys(("CLASSIFIERS", "EvalConfig", "evaluate", "trial_cv"), "experiments"),
    **dict.fromkeys(("DESCRIPTOR_MODES", "compute_bank", "select_features"), "bank"),
    **dict.fromkeys(("common_length_frames", "draw_windows", "parse_trials"), "sampling"),
}


def __getattr__(name: str):
    if name in _HOME:
        return getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
