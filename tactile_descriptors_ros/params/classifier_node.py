"""Parameters of ``classifier_node``: online material recognition from descriptors and labels."""

from __future__ import annotations

from ..core.labels import (
    DEFAULT_CLOCK_JUMP_S,
    DEFAULT_LABEL_HOLD_S,
    DEFAULT_LABEL_WAIT_S,
    DEFAULT_MAX_CLASS_NAME_CHARS,
    DEFAULT_MAX_CLASSES,
    DEFAULT_MAX_ID_STEP,
    MAX_CLASS_NAME_CHARS,
    MAX_CLASSES,
    MAX_HORIZON,
    MAX_ID_STEP,
    MAX_WAIT_S,
)
from ..core.learning import PA_UPDATES, RECOMMENDED_PA_AVERAGE, RECOMMENDED_PA_UPDATE
from ..errors import ConfigError
from .common import diagnostics_period, qos, robot
from .schema import NodeSchema, Param, join

__all__ = ["CLASSIFIER_NODE", "PREDICTION_ORDERS", "ETA_RANGE"]

#: ``prediction_order``: predict a descriptor on arrival, or in stamp order (bit-identical replays).
PREDICTION_ORDERS = ("immediate", "stamp")
#: Bounds of the learning rate eta (eq. 32): a larger or smaller one is a typo, and inf cannot be saved.
ETA_RANGE = (1e-6, 1e6)


def _frame_id_or_empty(value: str) -> None:
    if any(c.isspace() for c in value):
        raise ConfigError(f"must not hold blanks, got {value!r}")


CLASSIFIER_NODE = NodeSchema("classifier_node", join(
    robot("robot name or YAML path: the default model folder is per robot ('' = no robot folder)"),
    Param("model_path", "string", "model file (JSON), or a folder (ending in /) of one model per descriptor layout "
          "('~' expanded); '' = the folder $ROS_HOME/tactile_descriptors_ros/<robot>/<namespace>/<node name>/ "
          "($ROS_HOME: ~/.ros); the parameter reads the path used", default=""),
    Param("eta", "double", "PA-I aggressiveness C (eq. 32; the paper uses 1), from the next update on",
          default=1.0, range=ETA_RANGE, tunable=True, apply="eta"),
    Param("log_activity", "bool", "learn from log(Activity) features", default=True),
    Param("standardize", "bool", "running standardisation of the features", default=True),
    Param("pa_update", "string", "online update: max_loss (Crammer et al.), prediction (the paper's eq. 30-32), or "
          "arow (second-order, shared covariance); a model loaded from a file keeps its own",
          default=RECOMMENDED_PA_UPDATE, choices=PA_UPDATES),
    Param("pa_average", "bool", "predict with the running mean of the PA weights (false: the paper's PA-I)",
          default=RECOMMENDED_PA_AVERAGE),
    Param("label_horizon", "integer", "descriptors kept for late labels, and early labels held; a smaller one "
          "forgets the oldest at once", default=100, range=(1, MAX_HORIZON), unit="descriptors", tunable=True,
          apply="label_horizon"),
    Param("label_expiry_explorations", "integer", "a held label expires when a descriptor this many ids past it "
          "arrives", default=10, range=(1, MAX_HORIZON), unit="explorations"),
    Param("max_class_name_chars", "integer", "longest class name accepted", default=DEFAULT_MAX_CLASS_NAME_CHARS,
          range=(1, MAX_CLASS_NAME_CHARS), unit="characters"),
    Param("max_classes", "integer", "most classes: a label naming a new class beyond them is refused",
          default=DEFAULT_MAX_CLASSES, range=(1, MAX_CLASSES), unit="classes"),
    Param("max_exploration_id_step", "integer", "an exploration id farther than this from the latest is refused "
          "for labels (and, for a descriptor, moves nothing)", default=DEFAULT_MAX_ID_STEP, range=(1, MAX_ID_STEP),
          unit="explorations"),
    Param("label_hold_s", "double", "a label held for an exploration not seen yet expires after this long",
          default=DEFAULT_LABEL_HOLD_S, unit="s", range=(0.1, MAX_WAIT_S), tunable=True, apply="label_hold_s"),
    Param("prediction_order", "string", "immediate: predict a descriptor on arrival; stamp: after the labels "
          "stamped before its window end (a replay gives the same bits)", default=PREDICTION_ORDERS[0],
          choices=PREDICTION_ORDERS),
    Param("label_wait_s", "double", "longest wait of a stamped label for its descriptor, and with prediction_order "
          "stamp of a descriptor for the label due before it (0: arrival order)", default=DEFAULT_LABEL_WAIT_S,
          unit="s", range=(0.0, MAX_WAIT_S), tunable=True, apply="label_wait_s"),
    Param("clock_jump_s", "double", "a stamp this far behind the latest of its stream starts a new session (a "
          "replay started again)", default=DEFAULT_CLOCK_JUMP_S, unit="s", range=(0.001, MAX_WAIT_S)),
    Param("save_after_update", "bool", "make every update durable before it is reported (a synced journal entry)",
          default=True, tunable=True),
    Param("load_model", "bool", "load the model file if it exists", default=True),
    Param("enable_reset", "bool", "answer ~/reset (it erases the model; off: anyone on the ROS domain could call "
          "it)", default=False),
    Param("frame_id", "string", "header.frame_id of the predictions ('' = the descriptor's)", default="",
          tunable=True, check=_frame_id_or_empty, max_chars=256),
    diagnostics_period(),
    qos("descriptor", "reliable", "volatile", 50),
    qos("layout", "reliable", "transient_local", 100),
    qos("label", "reliable", "volatile", 1000, history="keep_all"),
    qos("prediction", "reliable", "volatile", 50),
))
