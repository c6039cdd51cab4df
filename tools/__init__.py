"""The stereocam command-line tools, one package per job; ``cli`` is the ``stereocam`` command tree."""
