"""``tactile simulate SCENE``: run a scene; save samples and ground truth, or the sensors' wire bytes.

Examples::

    tactile simulate demo_shadow_hand -o demo.npz
    tactile simulate demo_nao --wire skin-serial -o nao.bin
    tactile simulate config/scenes/nao_large_objects.yaml --json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ["register", "run"]

WIRE_FORMATS = ("bridge", "skin-serial")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("simulate", help="simulate a scene (samples, ground truth, wire bytes)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="a shipped scene name (see config/scenes) or a YAML path")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="write samples and ground truth (.npz; long scenes: one file per chunk, "
                        "<stem>_<k>.npz), or with --wire the byte stream")
    p.add_argument("--wire", choices=WIRE_FORMATS, default=None,
                   help="write the sensors' wire bytes instead: BioTac USB-serial bridge or skin serial framing")
    p.add_argument("--seed", type=int, default=None, help="override the scene's seed")
    p.add_argument("--chunk-s", type=float, default=60.0, help="simulate in chunks of about this many seconds")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..sim.engine import iter_simulate
    from ..sim.scene import load_scene
    from ..sim.sources import BiotacBridgeSource, SkinSerialSource

    scene = load_scene(args.scene, seed=args.seed)
    t0 = time.perf_counter()
    summary = {"scene": scene.name, "robot": scene.robot.name, "seed": scene.seed,
               "explorations": len(scene.explorations), "simulated_s": round(scene.duration_s, 3),
               "effects": sorted(scene.effects), "outputs": []}
    if args.wire:
        source_cls = BiotacBridgeSource if args.wire == "bridge" else SkinSerialSource
        src = source_cls(scene, chunk_s=args.chunk_s)
        n_bytes = 0
        out = open(args.output, "wb") if args.output else None  # noqa: SIM115 - closed below
        try:
            for _, frame in _progress(src, scene, args.json):
                n_bytes += len(frame)
                if out:
                    out.write(frame)
        finally:
            if out:
                out.close()
        summary["wire"] = {"format": args.wire, "bytes": n_bytes}
        if args.output:
            summary["outputs"].append(str(args.output))
    else:
        faults: dict[str, int] = {}
        clipped = 0
        chunks = iter_simulate(scene, max_chunk_s=args.chunk_s)
        for k, res in enumerate(_progress_chunks(chunks, scene, args.json)):
            for key, v in res.faults.items():
                if isinstance(v, int):
                    faults[key] = faults.get(key, 0) + v
            clipped += int(res.stats.get("clipped_samples", 0))
            if args.output:
                path = args.output if k == 0 else args.output.with_name(f"{args.output.stem}_{k}{args.output.suffix}")
                res.save_npz(path)
                summary["outputs"].append(str(path))

        summary["faults"] = faults
        summary["clipped_samples"] = clipped
    wall = time.perf_counter() - t0
    summary["wall_s"] = round(wall, 3)
    summary["simulated_s_per_wall_s"] = round(scene.duration_s / wall, 2) if wall > 0 else None
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{scene.name}: {summary['explorations']} explorations, {summary['simulated_s']:.1f} s simulated "
              f"in {wall:.2f} s ({summary['simulated_s_per_wall_s']}x real time)")
        for path in summary["outputs"]:
            print(f"  wrote {path}")
    return 0


def _progress_chunks(chunks, scene, quiet):
    from tqdm import tqdm

    bar = tqdm(total=len(scene.explorations), desc="simulate", unit="touch", disable=quiet, file=sys.stderr)
    for res in chunks:
        bar.update(len(res.explorations))
        yield res
    bar.close()


def _progress(items, scene, quiet):
    from tqdm import tqdm

    bar = tqdm(total=round(scene.duration_s, 1), desc="simulate", unit="s", disable=quiet, file=sys.stderr)
    last = scene.start_ns
    for t, item in items:
        if t - last >= 1_000_000_000:
            bar.update(round((t - last) * 1e-9, 1))
            last = t
        yield t, item
    bar.close()
