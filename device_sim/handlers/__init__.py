"""The firmware's command handlers: each module answers a group of requests (SPEC §4, §12)."""
