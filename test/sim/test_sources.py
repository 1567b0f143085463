"""Simulated sensors speak the real wire formats: the real decoders read back exactly the simulated samples."""

from __future__ import annotations

import copy
import time

import numpy as np
import pytest

from tactile_descriptors_ros.codecs.biotac_spi import BiotacFrameDecoder, FramePattern, command_byte
from tactile_descriptors_ros.codecs.bridge_serial import BridgeDecoder
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder
from tactile_descriptors_ros.codecs.skin_serial import SkinSerialDecoder
from tactile_descriptors_ros.sim import parse_scene, simulate
from tactile_descriptors_ros.sim.sources import (
    BiotacBridgeSource,
    SkinCanSource,
    SkinSerialSource,
    biotac_spi_bus,
    bridge_frames,
)
from tactile_descriptors_ros.transports.simulated import SimulatedTransport

HAND = {
    "scene": {"name": "wire", "robot": "shadow_hand", "seed": 4, "lead_in_s": 0.3},
    "effects": {"normal_force": {}, "texture_vibration": {}, "electrode_deformation": {}, "adc": {}},
    "explorations": [{"material": "cork", "body_parts": ["index", "thumb"], "duration_s": 1.0, "pause_s": 0.3}],
}
NAO = {
    "scene": {"name": "wire", "robot": "nao", "seed": 4, "lead_in_s": 0.2},  # robot replaced by a small copy
    "effects": {"normal_force": {}, "texture_vibration": {}, "proximity": {}, "adc": {}},
    "explorations": [{"material": "steel", "body_parts": ["right_hand"], "duration_s": 0.4, "pause_s": 0.1}],
}


@pytest.fixture(scope="module", autouse=True)
def small_nao(tmp_path_factory):
    """NAO's skin cell type on two body parts of three cells (the wire tests decode every frame in Python)."""
    import yaml

    from tactile_descriptors_ros.core.robot import robot_config_path

    data = yaml.safe_load(robot_config_path("nao").read_text())
    data["body_parts"] = [{"name": "right_hand", "cell_type": "skin_cell", "cells": [{"id": 15}, {"id": 16}, {"id": 17}]},
                          {"name": "chest", "cell_type": "skin_cell", "cells": [{"id": 20}, {"id": 21}, {"id": 22}]}]
    data.pop("nodes", None)
    data.pop("geometry", None)  # cells picked for the wire, not placed on the robot
    path = tmp_path_factory.mktemp("robot") / "small_nao.yaml"
    path.write_text(yaml.safe_dump(data))
    NAO["scene"]["robot"] = str(path)
    NAO["explorations"][0]["body_parts"] = ["right_hand", "chest"]
    yield path


def _scene(base, **effects):
    data = copy.deepcopy(base)
    data["effects"].update(effects)
    return parse_scene(data)


def _read_all(transport):
    out = bytearray()
    while chunk := transport.read(65536):
        out += chunk
    return bytes(out)


def test_bridge_stream_decodes_to_the_simulated_frames():
    scene = _scene(HAND)
    truth = simulate(scene)
    with SimulatedTransport(BiotacBridgeSource(scene)) as tr:
        data = _read_all(tr)
    bridge = BridgeDecoder()
    frames = bridge.feed(data)
    assert bridge.stats.crc_errors == 0 and bridge.stats.lost_frames == 0
    dec = BiotacFrameDecoder(FramePattern.default(), sensors=range(5))
    cell = truth.cells[1]  # index, chip select 1
    mine = [f for f in frames if f.chip_select == 1]
    assert len(mine) == cell.streams["pdc"].seq.size
    for k in (0, len(mine) // 2, len(mine) - 1):
        fr = dec.decode(1, mine[k].payload, mine[k].sequence)
        assert np.array_equal(fr.pac, cell.streams["pac"].counts[0, 22 * k : 22 * (k + 1)])
        assert np.array_equal(fr.electrodes, cell.streams["electrodes"].counts[:, k])
        assert fr.pdc == cell.streams["pdc"].counts[0, k] and fr.valid


def test_bridge_faults_reach_the_decoders_counters():
    scene = _scene(HAND, dropped_frames={"probability": 0.02}, bad_parity={"probability": 0.002},
                   corrupt_frames={"probability": 0.01})
    truth = simulate(scene)
    frames = bridge_frames(truth)
    bridge = BridgeDecoder()
    decoded = bridge.feed(b"".join(f for _, f in frames))
    corrupt = truth.faults["corrupt_frames"]
    dropped = truth.faults["dropped_frames"]
    assert corrupt > 0 and dropped > 0
    # a corrupt frame that was also dropped never reaches the wire
    sent_corrupt = sum(int((c.streams["pdc"].fault == 2).sum()) for c in truth.cells.values())
    assert bridge.stats.crc_errors == sent_corrupt
    assert bridge.stats.lost_frames >= dropped - 5  # drops at the very end show no gap
    dec = BiotacFrameDecoder(FramePattern.default(), sensors=range(5))
    parity = 0
    for f in decoded:
        parity += dec.decode(f.chip_select, f.payload, f.sequence).counts.parity
    expected = sum(int((st.fault == 1).sum()) for c in truth.cells.values() for st in c.streams.values()
                   if True)
    # words of corrupt (CRC-rejected) frames are not decoded
    assert 0 < parity <= expected


def test_spi_bus_answers_sampling_commands_with_simulated_values():
    truth = simulate(_scene(HAND))
    bus = biotac_spi_bus(truth)
    pac = []
    for _ in range(3):
        bus.transfer(1, bytes([command_byte("PAC"), 0]))
        word = bus.transfer(1, b"\x00\x00")
        hi, lo = word
        pac.append(((hi >> 1) << 5) | (lo >> 3))
    assert pac == truth.cells[1].streams["pac"].counts[0, :3].tolist()


def test_skin_can_messages_decode_to_the_simulated_samples():
    scene = _scene(NAO, dropped_frames={"probability": 0.01}, corrupt_frames={"probability": 0.01})
    truth = simulate(scene)
    tr = SimulatedTransport(SkinCanSource(scene))
    tr.open()
    dec = SkinCanDecoder(known_cell_ids=list(truth.cells))
    samples = []
    while (msg := tr.recv(0.0)) is not None:
        s = dec.decode(msg)
        if s is not None:
            samples.append(s)
    tr.close()
    cell = truth.cells[15]  # right hand
    acc = [s.values for s in samples if s.cell_id == 15 and s.modality == 1]
    st = cell.streams["accel"]
    good = st.counts[:, (st.fault == 0).all(axis=0)].T
    assert [tuple(v) for v in good.tolist()] == acc
    assert dec.stats.bad_length == truth.faults["corrupt_frames"] - _corrupt_dropped(truth)
    assert dec.stats.lost_frames > 0


def _corrupt_dropped(truth):
    """Corrupt frames that were also dropped (never sent)."""
    sent = sum(int((st.fault == 2).any(axis=0).sum()) for c in truth.cells.values() for st in c.streams.values())
    return truth.faults["corrupt_frames"] - sent


def test_skin_serial_stream_decodes():
    scene = _scene(NAO, corrupt_frames={"probability": 0.005})
    truth = simulate(scene)
    src = SkinSerialSource(scene)
    data = b"".join(f for _, f in src)
    dec = SkinSerialDecoder(known_cell_ids=list(truth.cells))
    samples = dec.feed(data)
    sent_corrupt = truth.faults["corrupt_frames"] - _corrupt_dropped(truth)
    assert dec.stats.crc_errors == sent_corrupt
    force = [s.values for s in samples if s.cell_id == 20 and s.modality == 2]
    st = truth.cells[20].streams["force"]
    assert [tuple(v) for v in st.counts[:, (st.fault == 0).all(axis=0)].T.tolist()] == force


def test_paced_source_hands_out_data_on_the_wall_clock():
    now = [0.0]
    src = BiotacBridgeSource(_scene(HAND), speed=2.0, clock=lambda: now[0])
    src.open()
    frame_bytes = 12 + 88 + 4
    assert src.read(1 << 20) == b""  # a frame is sent once its last word was sampled, 9.8 ms after its start
    now[0] += 0.005
    assert len(src.read(1 << 20)) == 5 * frame_bytes  # the five BioTacs' frames of t = 0
    now[0] += 0.125  # 0.25 s of simulated time at twice real time: 25 more frames each
    assert len(src.read(1 << 20)) == 5 * 25 * frame_bytes
    assert src.read(1 << 20) == b""


def test_bad_speed_is_rejected():
    from tactile_descriptors_ros.errors import SceneError

    with pytest.raises(SceneError):
        BiotacBridgeSource(_scene(HAND), speed=0.0)


def test_bridge_source_announces_serial_numbers_and_serves_only_its_chip_selects():
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeFrameType

    scene = _scene(HAND)
    with SimulatedTransport(BiotacBridgeSource(scene, chip_selects={1}, serial_prefix="BTSIM")) as tr:
        frames = BridgeDecoder().feed(_read_all(tr))
    assert {f.chip_select for f in frames} == {1}
    assert frames[0].kind == BridgeFrameType.SERIAL_NUMBER and frames[0].payload == b"BTSIM00000000001"
    assert all(f.kind == BridgeFrameType.SAMPLE for f in frames[1:])
    assert len(frames) - 1 == simulate(scene).cells[1].streams["pdc"].seq.size


def test_scene_for_another_robot_is_refused():
    from tactile_descriptors_ros.errors import SceneError
    from tactile_descriptors_ros.sim.sources import load_scene_for

    assert load_scene_for(_scene(HAND), "shadow_hand").name == "wire"
    with pytest.raises(SceneError, match="not 'nao'"):
        load_scene_for(_scene(HAND), "nao")


def _reference_rows(scene):
    """Per-row reference of the old source: one SkinSample per row, encoded by the per-sample encoders."""
    from tactile_descriptors_ros.sim.sources import SkinRows

    rows = SkinRows(simulate(scene))
    return rows, [rows.sample(i) for i in range(len(rows))]


def test_skin_rows_are_every_streams_samples_in_time_modality_cell_order():
    """One row per sample of every skin stream (dropped frames left out, corrupt ones flagged), ordered by
    time, then modality, then cell id, then the stream's own order, built the slow way here."""
    from tactile_descriptors_ros.sim.engine import FAULT_CORRUPT
    from tactile_descriptors_ros.sim.sources import SKIN_STREAM_MODALITY, SkinRows

    result = simulate(_scene(NAO, dropped_frames={"probability": 0.02}, corrupt_frames={"probability": 0.02}))
    ref = []
    for cell in result.cells.values():
        for name, mod in SKIN_STREAM_MODALITY.items():
            st = cell.streams.get(name) if cell.kind == "skin" else None
            for j in range(0 if st is None else st.seq.size):
                vals = [int(v) for v in st.counts[:, j]] + [0] * (3 - st.counts.shape[0])
                ref.append(((int(st.t_ns[j]), mod, cell.cell_id, j), int(st.seq[j]) & 0xFF, tuple(vals),
                            bool((st.fault[:, j] == FAULT_CORRUPT).any())))
    ref.sort(key=lambda r: r[0])
    rows = SkinRows(result)
    got = list(zip(rows.t_ns.tolist(), rows.modality.tolist(), rows.cell_id.tolist(), rows.sequence.tolist(),
                   map(tuple, rows.value_array.tolist()), rows.corrupt.tolist()))
    assert got == [(k[0], k[1], k[2], q, v, bad) for k, q, v, bad in ref]
    assert rows.corrupt.any() and len({k[1] for k, *_ in ref}) == 4  # every modality, some frames corrupt


def test_skin_can_batch_source_sends_the_per_sample_encoders_frames():
    from tactile_descriptors_ros.codecs.can_frames import messages_from_frames
    from tactile_descriptors_ros.codecs.skin_can import encode_can_message

    scene = _scene(NAO, dropped_frames={"probability": 0.01}, corrupt_frames={"probability": 0.01})
    rows, ref = _reference_rows(scene)
    tr = SimulatedTransport(SkinCanSource(scene))
    tr.open()
    parts = []
    while len(f := tr.recv_batch(777, 0.0)):
        assert len(f) <= 777
        parts.append(f)
    frames = np.concatenate(parts)
    assert len(frames) == len(ref) and rows.corrupt.any()
    for s, bad, got in zip(ref, rows.corrupt, messages_from_frames(frames)):
        want = encode_can_message(s)
        if bad:
            want.data = want.data[:-1]
            want.dlc = len(want.data)
        assert want.equals(got, timestamp_delta=0.0)
    # the batch decoder over the frame arrays equals the per-message decoder over the messages
    a, b = SkinCanDecoder(known_cell_ids=[15, 16, 17, 20]), SkinCanDecoder(known_cell_ids=[15, 16, 17, 20])
    batch = [s for p in parts for s in a.decode_frames(p).to_samples()]
    assert batch == b.decode_many(messages_from_frames(frames)) and a.stats == b.stats
    assert a.stats.unknown_cells > 0 and a.stats.bad_length > 0


def test_skin_serial_batch_source_sends_the_per_sample_encoders_bytes():
    from tactile_descriptors_ros.codecs.skin_serial import encode_skin_frame

    scene = _scene(NAO, corrupt_frames={"probability": 0.01})
    rows, ref = _reference_rows(scene)
    want = bytearray()
    for s, bad in zip(ref, rows.corrupt):
        f = bytearray(encode_skin_frame(s))
        if bad:
            f[-5] ^= 0x5A
        want += f
    tr = SimulatedTransport(SkinSerialSource(scene))
    tr.open()
    got = bytearray()
    while chunk := tr.read(1000):
        assert len(chunk) <= 1000
        got += chunk
    assert bytes(got) == bytes(want) and rows.corrupt.any()


def test_paced_can_batches_hand_out_only_due_frames():
    now = [0.0]
    src = SkinCanSource(_scene(NAO), speed=1.0, clock=lambda: now[0])
    src.open()
    first = src.recv_batch(1 << 20, 0.0)
    assert len(first) and (first["timestamp"] <= 0.0 + 1e-12).all()
    now[0] += 0.1
    more = src.recv_batch(1 << 20, 0.0)
    assert len(more) and more["timestamp"].max() <= 0.1 + 1e-9 and more["timestamp"].min() > 0.0
    assert not len(src.recv_batch(1 << 20, 0.0))


@pytest.mark.parametrize("wire", ["can", "serial"])
def test_wire_throughput_reports_every_frame_and_agrees_with_the_per_frame_path(wire):
    from tactile_descriptors_ros.sim.sources import SkinRows, wire_throughput

    scene = _scene(NAO, dropped_frames={"probability": 0.01}, corrupt_frames={"probability": 0.01})
    rows = SkinRows(simulate(scene))
    out = wire_throughput(scene, wire, reference_frames=500)
    sent = len(rows)
    if wire == "can":
        assert out["frames"] == sent
        assert out["decoder_stats"]["samples"] == sent - int(rows.corrupt.sum()) - out["decoder_stats"]["unknown_cells"]
    else:  # delivered samples: corrupt frames fail their CRC
        assert out["frames"] == sent - int(rows.corrupt.sum())
    assert out["reference_frames"] == 500 and out["batch_frames_per_s"] > 0 and out["simulated_s"] > 0


def test_a_paced_source_simulates_the_next_chunk_while_the_reader_takes_this_one():
    """Live (paced), the chunk after the one being read is simulated on a worker thread at once, so a reader
    never waits for a whole chunk's simulation between two reads; the frames are those of the unpaced
    source, in the same order."""
    import threading

    data = copy.deepcopy(NAO)
    data["explorations"] = [dict(data["explorations"][0], material=m) for m in ("steel", "cork", "felt")]
    scene = parse_scene(data)
    src = SkinCanSource(scene, speed=1e6, chunk_s=0.5)
    converting, release = threading.Event(), threading.Event()
    convert = src._convert
    calls = []

    def gated(result):
        calls.append(threading.current_thread().name)
        if len(calls) == 2:  # the second chunk: hold its simulation until the reader has read on
            converting.set()
            assert release.wait(60.0)
        return convert(result)

    src._convert = gated
    src.open()
    first = src.recv_batch(100, 0.0)  # the first chunk is queued and the second starts on the worker
    assert len(first) == 100
    assert converting.wait(60.0), "the next chunk was not simulated while this one was read"
    rest_of_first = src.recv_batch(len(src._items[0]), 0.0)  # the first chunk to its end, the second still held
    release.set()
    rest = src.recv_batch(10**7, 0.0)
    while len(more := src.recv_batch(10**7, 0.0)):
        rest = np.concatenate([rest, more])
    # every chunk on the worker, also the first (waited for): the simulator's CPU is that one thread's
    assert len(calls) >= 3 and all(c.startswith("scene_ahead") for c in calls), calls
    assert src.thread_id is not None and src.thread_id != threading.get_native_id()
    plain = SkinCanSource(scene, chunk_s=0.5)
    plain.open()
    want = plain.recv_batch(10**8, 0.0)
    got = np.concatenate([first, rest_of_first, rest])
    assert len(got) == len(want) > 0 and (got == want).all()


def test_a_paced_source_keeps_two_chunks_simulated_ahead_of_the_reader():
    """A short chunk followed by one that is slow to simulate must not stall the reader: while the first chunk
    is still being read, the worker simulates the second and then the third, without a further read; the frames
    are still those of the unpaced source, in order."""
    import threading

    from tactile_descriptors_ros.sim.sources import AHEAD_CHUNKS

    assert AHEAD_CHUNKS == 2
    data = copy.deepcopy(NAO)
    data["explorations"] = [dict(data["explorations"][0], material=m) for m in ("steel", "cork", "felt", "cotton")]
    scene = parse_scene(data)
    src = SkinCanSource(scene, speed=1e6, chunk_s=0.5)
    third = threading.Event()
    convert = src._convert
    calls = []

    def noting(result):
        calls.append(threading.current_thread().name)
        if len(calls) == 3:
            third.set()
        return convert(result)

    src._convert = noting
    src.open()
    first = src.recv_batch(100, 0.0)
    assert len(first) == 100
    assert third.wait(60.0), f"only {len(calls)} chunks simulated while the first was read"
    assert calls[1].startswith("scene_ahead") and calls[2].startswith("scene_ahead")
    rest = src.recv_batch(10**7, 0.0)
    while len(more := src.recv_batch(10**7, 0.0)):
        rest = np.concatenate([rest, more])
    plain = SkinCanSource(scene, chunk_s=0.5)
    plain.open()
    want = plain.recv_batch(10**8, 0.0)
    got = np.concatenate([first, rest])
    assert len(got) == len(want) > 0 and (got == want).all()


def test_a_simulated_transport_reports_the_simulators_cpu_and_thread():
    """The driver's diagnostics say what simulating took and on which thread, so a bench can tell the
    simulator's CPU from the driver's own; an unpaced source simulates on the reader's thread and has none."""
    import threading

    from tactile_descriptors_ros.transports.simulated import SimulatedTransport

    scene = parse_scene(copy.deepcopy(NAO))
    for speed, on_worker in ((1e6, True), (None, False)):
        transport = SimulatedTransport(SkinCanSource(scene, speed=speed, chunk_s=0.5))
        transport.open()
        before = time.thread_time()
        assert len(transport.source.recv_batch(1000, 0.0)) == 1000
        here_s = time.thread_time() - before
        described = transport.describe()
        assert described["simulator_cpu_s"] > 0.0
        if on_worker:
            assert described["simulator_thread_id"] not in (None, threading.get_native_id())
        else:  # simulated here, within this thread's CPU time
            assert "simulator_thread_id" not in described and described["simulator_cpu_s"] <= here_s + 1e-3
