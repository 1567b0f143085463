"""Short fuzz passes of every codec, and proof that the fuzzer catches broken decoders."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_descriptors_lab import fuzz
from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs.framing import SequenceEvent, SequenceTracker
from tactile_descriptors_ros.errors import ConfigError


@pytest.mark.parametrize("codec", sorted(fuzz.FUZZERS))
def test_short_fuzz_pass(codec):
    ticks = []
    report = fuzz.fuzz_codec(codec, 2000, seed=3, progress=ticks.append)
    assert report.ok, report.examples
    assert sum(ticks) == 2000
    assert sum(report.mutations.values()) >= 2000
    assert sum(report.checked.values()) > 1000
    assert len(report.mutations) >= 7  # every fault class was exercised
    json.dumps(report.as_dict())


def test_fuzzer_catches_a_decoder_that_ignores_parity(monkeypatch):
    lax = np.where(np.asarray(spi._STATUS_TABLE) == spi.WordStatus.PARITY, 0, spi._STATUS_TABLE).astype(np.uint8)
    monkeypatch.setattr(spi, "_STATUS_TABLE", lax)
    report = fuzz.fuzz_biotac_spi(3000, seed=1)
    assert not report.ok
    assert any("reference decoder" in e for e in report.examples)


def test_fuzzer_catches_a_decoder_that_passes_duplicates(monkeypatch):
    real = SequenceTracker.update

    def no_dups(self, key, seq, *args):
        event = real(self, key, seq, *args)
        return SequenceEvent.IN_ORDER if event is SequenceEvent.DUPLICATE else event
    monkeypatch.setattr(SequenceTracker, "update", no_dups)
    for codec in ("bridge_serial", "skin_can", "skin_serial"):
        assert not fuzz.fuzz_codec(codec, 1500, seed=2).ok


def test_unknown_codec():
    with pytest.raises(ConfigError):
        fuzz.fuzz_codec("i2c", 10)


def test_fuzz_command_json(capsys):
    import argparse

    from tactile_descriptors_lab.verbs import cmd_fuzz

    parser = argparse.ArgumentParser(prog="tactile")
    cmd_fuzz.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["fuzz", "--codec", "skin_serial", "--inputs", "300", "--seed", "4", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["codecs"][0]["codec"] == "skin_serial" and out["codecs"][0]["inputs"] == 300
