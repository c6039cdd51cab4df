"""The checks, one module per area; importing this package registers them in running order."""
from . import identity, config, cross_rules, streaming, triggers, link, robustness, new_links, time_sync, calibration, update, formats, post, session  # noqa: F401,E501
