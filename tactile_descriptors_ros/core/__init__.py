"""The pure core: descriptors, alignment, gating, aggregation, windowing, learning.

Imports numpy, scipy and PyYAML only -- never rclpy -- so it runs in
notebooks, evaluation scripts and tests without ROS (a test checks this).
"""

from .aggregation import CellSignals, RobotDescriptor, describe_window
from .descriptors import Hjorth, Quality, hjorth, pearson, spearman
from .learning import OnlineClassifier, PassiveAggressive
from .robot import RobotDescription, load_robot
from .windowing import CellChunk, Window, Windower

__all__ = [
    "CellChunk",
    "CellSignals",
    "Hjorth",
    "OnlineClassifier",
    "PassiveAggressive",
    "Quality",
    "RobotDescription",
    "RobotDescriptor",
    "Window",
    "Windower",
    "describe_window",
    "hjorth",
    "load_robot",
    "pearson",
    "spearman",
]
