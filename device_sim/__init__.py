"""The simulated STOC-class camera: firmware, sensor rig, matching core and its servers.

The SDK reaches it only through the entry points it declares (pyproject.toml): the ``sim://`` and
``replay://`` URL schemes (``stereocam.url_schemes``) and the simulated USB bus (``stereocam.usb_backends``).
"""
from .firmware import SimulatedCamera
from .ground_truth import GroundTruth
from .trigger import TriggerLine

__all__ = ["SimulatedCamera", "GroundTruth", "TriggerLine"]
