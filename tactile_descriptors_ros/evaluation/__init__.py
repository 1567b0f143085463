"""Evidence on real data: descriptor modes, the paper's learners, protocols and the report.

Modules: :mod:`.windows` (trial ranges, crop rule, seeded windows),
:mod:`.features` (feature bank and named descriptor modes), :mod:`.classifiers`
(SVM with the paper's C grid, PA-I curve, GMM/NMI), :mod:`.experiments`
(one split, trial CV) and :mod:`.report` (``tactile report``).
"""

from .classifiers import C_GRID, C_GRID_TEXT, SCALINGS, fit_svm, gmm_nmi, pa_curve
from .experiments import CLASSIFIERS, EvalConfig, evaluate, trial_cv
from .features import DESCRIPTOR_MODES, compute_bank, select_features
from .windows import common_length_frames, draw_windows, parse_trials

__all__ = [
    "C_GRID", "C_GRID_TEXT", "SCALINGS", "fit_svm", "gmm_nmi", "pa_curve",
    "CLASSIFIERS", "EvalConfig", "evaluate", "trial_cv",
    "DESCRIPTOR_MODES", "compute_bank", "select_features",
    "common_length_frames", "draw_windows", "parse_trials",
]
