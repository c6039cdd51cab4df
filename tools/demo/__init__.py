"""stereocam demo: a simulator (or a group of them) streamed, with outputs and a summary."""
