"""The simulated STOC-class camera: firmware, sensor rig, matching core and its servers.

Importing it registers the ``sim://`` and ``replay://`` URL schemes and the simulated USB bus with the SDK.
"""
from stereocam.transports import register_scheme

from .firmware import SimulatedCamera
from .ground_truth import GroundTruth
from .trigger import TriggerLine

register_scheme("sim", "stereocam.device_sim.links.inprocess")
register_scheme("replay", "stereocam.device_sim.links.replay")

__all__ = ["SimulatedCamera", "GroundTruth", "TriggerLine"]
