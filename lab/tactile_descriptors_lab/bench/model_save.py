"""``tactile bench --model-save``: what saving one label costs, journal against whole-file rewrite.

The classifier node makes every update durable before it reports it.  This
measures, on a model of ``classes`` classes, the wall time per label of

* the journal (:class:`~tactile_descriptors_ros.core.model_store.ModelStore`:
  one synced line per update, written over zeros reserved ahead of it, so
  ``fdatasync`` commits no metadata; compaction and extensions included when
  they happen),
* the same journal appending without a reserve (``reserve_bytes=0``: every
  sync also commits the file's new size), and
* the whole-file atomic rewrite (:func:`~tactile_descriptors_ros.core.model_store.save_model`, what every
  label cost before the journal),

in the same run and the same folder, so the ratio holds on a loaded machine
even when the absolute times do not; and the floor of any durable save there
(one line appended and ``fdatasync`` ed), which the journal cannot beat.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from tactile_descriptors_ros.core.learning import RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE, OnlineClassifier
from tactile_descriptors_ros.core.model_store import ModelStore, load_model, save_model

__all__ = ["measure_model_save", "format_model_save"]


def _model(classes: int, features: int, rng: np.random.Generator) -> OnlineClassifier:
    clf = OnlineClassifier([f"index/A_{i}" for i in range(features)], update=RECOMMENDED_PA_UPDATE,
                           average=RECOMMENDED_PA_AVERAGE)
    for c in range(classes):  # every class learned once: non-zero rows, as a used model has
        v = rng.uniform(0.5, 5.0, features)
        clf.observe(v)
        clf.learn(v, f"material_{c}")
    return clf


def _summary(seconds: list[float]) -> dict:
    ms = np.asarray(seconds) * 1e3
    return {"n": int(ms.size), "median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)),
            "max_ms": float(ms.max()), "mean_ms": float(ms.mean())}


def measure_model_save(classes: int = 1000, labels: int = 50, features: int = 8, seed: int = 0,
                       folder: str | None = None) -> dict:
    """Time ``labels`` durable saves each way on a model of ``classes`` classes.

    Parameters
    ----------
    classes : int
        Classes in the model (1,000: the target case).
    labels : int
        Labels timed per method.
    features : int
        Descriptor values (8: one BioTac finger).
    folder : str, optional
        Where to write (default: a temporary folder; the disk matters).

    Returns
    -------
    dict
        ``journal``, ``journal_append`` and ``rewrite`` summaries (ms per label), ``ratio`` (rewrite
        median / journal median), the model file's size and the settings.
    """
    if classes < 2 or labels < 1 or features < 1:
        raise ValueError("classes must be at least 2, labels and features at least 1")
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory(prefix="tactile_model_save_", dir=folder) as tmp:
        results: dict[str, list[float]] = {"journal": [], "journal_append": [], "rewrite": [], "sync": []}
        sizes = {}
        floor = open(Path(tmp) / "floor", "wb")  # noqa: SIM115 - closed below
        # the two journals label by label in turn, so a change of the machine's load hits both alike
        methods = {"journal": {}, "journal_append": {"reserve_bytes": 0}}
        clfs = {m: _model(classes, features, rng) for m in methods}
        stores = {m: ModelStore(Path(tmp) / f"{m}.json", **kw) for m, kw in methods.items()}
        for m in methods:
            stores[m].save(clfs[m])
        for k in range(labels):
            v = rng.uniform(0.5, 5.0, features)
            for m in methods:
                clfs[m].observe(v)
                clfs[m].learn(v, f"material_{k % classes}")
                start = time.perf_counter()
                stores[m].record(clfs[m])
                results[m].append(time.perf_counter() - start)
            # the floor of any durable save here, in the same conditions: one line appended and synced
            start = time.perf_counter()
            floor.write(b"x" * 64 + b"\n")
            floor.flush()
            os.fdatasync(floor.fileno()) if hasattr(os, "fdatasync") else os.fsync(floor.fileno())
            results["sync"].append(time.perf_counter() - start)
        floor.close()
        for m in methods:
            stores[m].close()
            if load_model(stores[m].path).version != clfs[m].version:
                raise RuntimeError(f"{m}: the saved model lacks labels")
        clf = _model(classes, features, rng)
        path = Path(tmp) / "rewrite.json"
        save_model(clf, path)
        for k in range(labels):
            v = rng.uniform(0.5, 5.0, features)
            clf.observe(v)
            clf.learn(v, f"material_{k % classes}")
            start = time.perf_counter()
            save_model(clf, path)
            results["rewrite"].append(time.perf_counter() - start)
        sizes["rewrite"] = path.stat().st_size
        if load_model(path).version != clf.version:
            raise RuntimeError("rewrite: the saved model lacks labels")
        journal, rewrite = _summary(results["journal"]), _summary(results["rewrite"])
    return {"classes": classes, "labels": labels, "features": features, "model_file_bytes": sizes["rewrite"],
            "journal": journal, "journal_append": _summary(results["journal_append"]), "rewrite": rewrite,
            "sync_floor": _summary(results["sync"]),
            "ratio": rewrite["median_ms"] / journal["median_ms"],
            "target_ms": 5.0, "target_met": journal["median_ms"] <= 5.0}


def format_model_save(res: dict) -> str:
    """The measurement as a few lines of text."""
    j, a, r = res["journal"], res["journal_append"], res["rewrite"]
    return "\n".join([
        f"model save per label: {res['classes']} classes x {res['features']} values "
        f"(file {res['model_file_bytes'] / 1e3:.0f} kB), {res['labels']} labels each, durable (synced) saves",
        f"  journal (ModelStore.record): median {j['median_ms']:.2f} ms, p95 {j['p95_ms']:.2f} ms, "
        f"max {j['max_ms']:.2f} ms",
        f"  journal without a reserve:   median {a['median_ms']:.2f} ms, p95 {a['p95_ms']:.2f} ms, "
        f"max {a['max_ms']:.2f} ms",
        f"  whole-file rewrite (save):   median {r['median_ms']:.2f} ms, p95 {r['p95_ms']:.2f} ms, "
        f"max {r['max_ms']:.2f} ms",
        f"  one-line append + fdatasync (the floor of any durable save here): median "
        f"{res['sync_floor']['median_ms']:.2f} ms",
        f"  rewrite / journal: {res['ratio']:.1f}x; target <= {res['target_ms']:.0f} ms per label: "
        f"{'met' if res['target_met'] else 'NOT met'}",
    ])
