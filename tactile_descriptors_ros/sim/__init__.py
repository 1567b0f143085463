"""Scene simulator: simulate only the effects a scene calls for, and feed the real drivers.

* :mod:`.scene` -- scenes as YAML (robot, effects, explorations), strictly validated;
* :mod:`.textures` -- per-material texture models fitted to real BioTac recordings
  (AR vibration, electrode statistics; the fitting is the lab's) and parametric materials;
* :mod:`.synthetic` -- synthetic skins, whole windows of signals and looped scenes;
* :mod:`.engine` -- :func:`simulate`: integer ADC counts per cell and stream with
  int64 ns time stamps, plus ground truth;
* :mod:`.sources` -- the simulated sensors' wire bytes, made by the real codecs' encoders.
"""

from .engine import CellRecord, ExplorationTiming, SimResult, Stream, iter_simulate, simulate
from .scene import EFFECTS, MOTIONS, Exploration, Scene, load_scene, parse_scene
from .textures import MaterialModel, get_material, material_library, parametric_material

__all__ = [
    "CellRecord",
    "ExplorationTiming",
    "SimResult",
    "Stream",
    "simulate",
    "iter_simulate",
    "EFFECTS",
    "MOTIONS",
    "Exploration",
    "Scene",
    "load_scene",
    "parse_scene",
    "MaterialModel",
    "get_material",
    "material_library",
    "parametric_material",
]
