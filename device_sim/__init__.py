"""The simulated STOC-class camera: firmware, sensor rig, matching core and its servers.

The SDK reaches it only through the entry points it declares (pyproject.toml): the ``sim://`` and
``replay://`` URL schemes (``stereocam.url_schemes``) and the simulated USB bus (``stereocam.usb_backends``).
"""
from stereocam.protocol.extras import raise_missing

try:
    from .firmware import SimulatedCamera
    from .ground_truth import GroundTruth
    from .trigger import TriggerLine
except ModuleNotFoundError as exc:  # numba: pip install 'stereocam[sim]'
    raise_missing(exc, "the simulated camera")

__all__ = ["SimulatedCamera", "GroundTruth", "TriggerLine"]
