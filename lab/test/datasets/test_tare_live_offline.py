"""One tare, live and offline: the readers and the drivers' streams rest at the same level from the same samples.

Shared BioTac trials go through the bridge wire into :class:`BiotacStream` (what the BioTac driver
runs) and through the table reader; simulated skin trials through the CAN wire into
:class:`SkinStream` (what the skin driver runs) and through the skin table reader.  Both sides
call :func:`tactile_descriptors_ros.core.tare.resting_level`; the levels must be equal bit for bit.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from writers import write_skin_csv

from tactile_descriptors_lab.datasets.biotac_slide import MAPPING, load_recordings
from tactile_descriptors_lab.datasets.layouts import simulated_skin_trials
from tactile_descriptors_lab.datasets.readers import read_source
from tactile_descriptors_lab.datasets.recording import trial_rest
from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder
from tactile_descriptors_ros.codecs.skin import Modality, SkinSampleBatch
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder, encode_can_frames
from tactile_descriptors_ros.core.tare import TRIAL_REST_PERCENTILE
from tactile_descriptors_ros.streams.biotac import BiotacStream, BridgeFrameSource, SensorConfig
from tactile_descriptors_ros.streams.skin import RECENT_FORCE, SkinStream
from tactile_descriptors_ros.transports.loopback import LoopbackTransport

#: Force scale of the BioTac finger (config/shadow_hand.yaml) [N/count]; the level does not depend on it.
PDC_N_PER_COUNT = 0.05


def _through_the_bridge(rec) -> BiotacStream:
    """Every frame of ``rec`` encoded on the bridge wire, read back and taken by a BioTac stream."""
    pattern = spi.FramePattern.default()
    assert pattern.pac_count == rec.pac_per_frame and pattern.electrode_count == rec.electrodes.shape[0]
    port = LoopbackTransport()
    port.open()
    source = BridgeFrameSource(port, pattern, [0], spi.BiotacFrameDecoder(pattern, [0]), read_timeout_s=0.0,
                               frame_period_ns=10_000_000)
    stream = BiotacStream({0: SensorConfig(0, "bt", "index", "bt")}, pattern, 4400.0, 10, "device", 0.0, 0.0, 0.0,
                          0.0, PDC_N_PER_COUNT, lambda: 0, Counter())
    enc = BridgeEncoder()
    t_us = (rec.frame_t_ns - rec.frame_t_ns[0]) // 1000
    k = rec.pac_per_frame
    for i in range(rec.n_frames):
        vals = {"PAC": rec.pac[i * k:(i + 1) * k].tolist(), "PDC": int(rec.pdc[i]), "TAC": int(rec.tac[i]),
                "TDC": int(rec.tdc[i]), "electrodes": rec.electrodes[:, i].tolist()}
        port.write(enc.encode(0, spi.encode_frame(pattern, vals), t_us=int(t_us[i])))
        for item in source.read():
            stream.add(item, host_ns=0)
    assert stream.state[0].frames_total == rec.n_frames and source.decode_errors == 0
    return stream


@pytest.mark.realdata
@pytest.mark.parametrize("raise_counts", [0, 840], ids=["as-recorded", "untared-by-840"])
def test_shared_trials_rest_at_the_readers_level_in_the_biotac_stream(biotac_data_dir, tmp_path, raise_counts):
    """Trial 1 of three materials, as recorded (tared and clipped at 0) and raised by 840 PDC and 2000
    electrode counts (an untared finger): the stream's tare over the whole trial at the trial's rest
    percentile is the reader's resting level, bit for bit, and the reader subtracts it rounded."""
    for rec in load_recordings(biotac_data_dir, trials=[1], materials=[1, 12, 18]):
        if raise_counts:
            rec = rec.__class__(**{**rec.__dict__, "pdc": rec.pdc + raise_counts, "electrodes": rec.electrodes + 2000})
            path = tmp_path / Path(rec.path).name
            _write_biotac_csv(rec, path)
        else:
            path = Path(rec.path)
        (tared,) = read_source(path, MAPPING, tare="per_trial")
        stream = _through_the_bridge(rec)
        st = stream.state[0]
        span_s = (rec.frame_t_ns[-1] - rec.frame_t_ns[0]) / 1e9 + 1.0
        ok, why = stream.tare_one(st, span_s, check_contact=False, rest_percentile=TRIAL_REST_PERCENTILE)
        assert ok, why
        rest = trial_rest(rec)
        assert st.tare_pdc == rest.reference[0]
        assert np.array_equal(st.tare_electrodes, rest.channels)
        assert tared.tare_counts == (float(np.round(st.tare_pdc)),)
        np.testing.assert_array_equal(tared.pdc, np.clip(rec.pdc - np.round(st.tare_pdc), 0, None))
        np.testing.assert_array_equal(tared.electrodes,
                                      np.clip(rec.electrodes - np.round(st.tare_electrodes)[:, None], 0, None))
        if raise_counts:  # an independent reading of the definition: medians of the frames at or below p5
            resting = rec.pdc <= np.percentile(rec.pdc, TRIAL_REST_PERCENTILE)
            assert st.tare_pdc == np.median(rec.pdc[resting]) >= raise_counts
            np.testing.assert_array_equal(st.tare_electrodes, np.median(rec.electrodes[:, resting], axis=1))


def _write_biotac_csv(rec, path: Path) -> None:
    """A trial in the shared recordings' CSV layout (one row a frame, every row ending with a comma)."""
    k = rec.pac_per_frame
    names = (["timestamp", "tdc", "tac", "pdc"] + [f"pac{j + 1}" for j in range(k)]
             + [f"ele{j + 1}" for j in range(rec.electrodes.shape[0])])
    lines = [",".join(names)]
    for i in range(rec.n_frames):
        row = ([f"{rec.frame_t_ns[i] // 10**9}.{rec.frame_t_ns[i] % 10**9:09d}", rec.tdc[i], rec.tac[i], rec.pdc[i]]
               + rec.pac[i * k:(i + 1) * k].tolist() + rec.electrodes[:, i].tolist())
        lines.append(",".join(str(v) for v in row) + ",")
    path.write_text("\n".join(lines) + "\n")


#: The simulated skin cell (NAO right hand) the skin trials come from.
SKIN_CELL = 15


def _through_the_can_bus(t_ns: np.ndarray, force: np.ndarray) -> SkinStream:
    """Force samples ``(3, n)`` stamped ``t_ns`` on the CAN wire, ten a read, taken by a skin stream."""
    stream = SkinStream({SKIN_CELL: ("right_hand", "cell15")}, 1000.0, 250.0, 0.05, "device", 0.0, 0.0, lambda: 0,
                        Counter())
    n = t_ns.size
    batch = SkinSampleBatch(np.full(n, SKIN_CELL, np.int64), np.full(n, int(Modality.FORCE), np.int64),
                            np.arange(n, dtype=np.int64) % 256, force.T.astype(np.int64), t_ns.astype(np.int64))
    frames = encode_can_frames(batch)
    decoder = SkinCanDecoder(known_cell_ids={SKIN_CELL})
    for a in range(0, n, 10):
        stream.add(decoder.decode_frames(frames[a:a + 10], None), int(t_ns[min(a + 9, n - 1)]))
    cell = stream.cells[SKIN_CELL]
    assert cell.samples == n and cell.lost == 0
    return stream


def test_simulated_skin_trials_rest_at_the_readers_level_in_the_skin_stream(tmp_path):
    """Simulated skin trials 200 counts off zero (above F_t at rest), their last RECENT_FORCE frames
    (the touch and the rest after it): the skin stream's tare over them at the trial's rest
    percentile is the reader's per-channel tare, bit for bit."""
    trials = []
    for tr in simulated_skin_trials(materials=("cork", "steel"), repeat=1):
        cut = slice(tr["t_ns"].size - RECENT_FORCE, None)
        k = tr["vibration"].shape[1] // tr["t_ns"].size
        trials.append({**tr, "t_ns": tr["t_ns"][cut], "force": tr["force"][:, cut], "proximity": tr["proximity"][cut],
                       "temperature": tr["temperature"][cut],
                       "vibration": tr["vibration"][:, (tr["t_ns"].size - RECENT_FORCE) * k:]})
    source = write_skin_csv(tmp_path / "csv", trials, force_offset=200)
    mapping = tmp_path / "skin.yaml"
    mapping.write_text(yaml.safe_dump(
        {"format": "csv", "files": "*/*.csv", "robot": "nao", "class": {"from": "folder"},
         "trial": {"from": "file", "pattern": r"trial_(\d+)$"},
         "channels": {"ax": "acc_x{i}", "ay": "acc_y{i}", "az": "acc_z{i}", "f1": "force1", "f2": "force2",
                      "f3": "force3", "proximity": "prox", "temperature": "temp_c"},
         "stamps": {"column": "t_ns", "unit": "ns"}, "tare": "per_trial"}))
    got = read_source(source, mapping)
    assert len(got) == len(trials) == 2
    for rec, tr in zip(got, sorted(trials, key=lambda t: t["class_name"])):
        stream = _through_the_can_bus(tr["t_ns"], tr["force"] + 200)
        cell = stream.cells[SKIN_CELL]
        ok, why = stream.tare_cell(cell, (tr["t_ns"][-1] - tr["t_ns"][0]) / 1e9 + 1.0,
                                   rest_percentile=TRIAL_REST_PERCENTILE)
        assert ok, why
        assert np.array_equal(cell.tare, np.asarray(rec.tare_counts))
        assert np.all(cell.tare > 200) and np.all(cell.tare < 240)  # the offset plus the cell's own rest


def test_simulated_pause_rests_at_the_protocols_level_in_the_skin_stream():
    """The simulated protocols tare each exploration on the pause after it; the skin stream given the
    same pause samples (``~/tare``: the whole window at rest) takes the same level, bit for bit."""
    from tactile_descriptors_lab.protocols import _tare, restrict_robot
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.sim import parse_scene, simulate

    scene = {"scene": {"name": "tare", "robot": "nao", "seed": 5, "lead_in_s": 0.5},
             "effects": {"normal_force": {"ramp_s": 0.1}, "texture_vibration": {}, "sensor_noise": {"std_counts": 2.0},
                         "adc": {}},
             "explorations": [{"materials": ["cork"], "repeat": 2, "body_parts": ["right_hand"], "motion": "lateral",
                               "force_n": 2.0, "speed_m_s": 0.03, "duration_s": 1.0, "pause_s": 0.8}]}
    res = simulate(restrict_robot(parse_scene(scene), ["right_hand"]))
    cell = res.cells[SKIN_CELL]
    ct = load_robot("nao").cell_types["skin_cell"]
    frc = cell.streams["force"]
    assert list(frc.channels) == list(ct.force.channels)
    for e in res.explorations:
        p0 = e.release_ns + 100_000_000
        p1 = e.release_ns + int(round(e.exploration.pause_s * 1e9)) - 1
        a, b = np.searchsorted(frc.t_ns, [p0, p1])
        assert (frc.fault[:, a:b] == 0).all() and b - a > 100
        stream = _through_the_can_bus(frc.t_ns[a:b], frc.counts[:, a:b])
        ok, why = stream.tare_cell(stream.cells[SKIN_CELL], (p1 - p0) / 1e9)
        assert ok, why
        assert np.array_equal(stream.cells[SKIN_CELL].tare, _tare(cell, ct, p0, p1))
