"""The simulated STOC-class camera: firmware, sensor rig, matching core and its servers."""
from .camera import GroundTruth, SimulatedCamera
from .trigger import TriggerLine

__all__ = ["SimulatedCamera", "GroundTruth", "TriggerLine"]
