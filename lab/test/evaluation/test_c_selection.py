"""Choosing the SVM's C: progress on stderr, the same scores as scikit-learn's grid search."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")  # the reference grid search's
def test_choosing_c_shows_progress_and_scores_as_a_grid_search(capsys):
    from sklearn.model_selection import GridSearchCV

    from tactile_descriptors_lab.evaluation.classifiers import _svm_pipeline, cv_splits, fit_svm

    rng = np.random.default_rng(0)
    y = np.repeat(np.arange(3), 12)
    X = rng.normal(size=(36, 4)) + y[:, None]
    groups = np.arange(36)
    labels = [f"f{i}" for i in range(4)]
    grid = (0.01, 1.0, 100.0)
    res = fit_svm(X, y, groups, labels, scaling="standardize", folds=3, repeats=2, c_grid=grid, progress=True)
    err = capsys.readouterr().err
    assert "choosing C" in err and "18/18" in err  # the bar counts fits: 3 C x 3 folds x 2 repeats
    search = GridSearchCV(_svm_pipeline("standardize", labels), {"svc__C": list(grid)},
                          cv=cv_splits(y, groups, 3, 2, 0), refit=False).fit(X, y)
    assert res.cv_scores == {c: float(m) for c, m in zip(grid, search.cv_results_["mean_test_score"])}


def test_fit_svm_is_quiet_without_progress(capsys):
    from tactile_descriptors_lab.evaluation.classifiers import fit_svm

    rng = np.random.default_rng(1)
    y = np.repeat(np.arange(2), 10)
    fit_svm(rng.normal(size=(20, 3)) + y[:, None], y, np.arange(20), ["a", "b", "c"], scaling="standardize",
            folds=2, repeats=1, c_grid=(1.0,))
    assert capsys.readouterr().err == ""
