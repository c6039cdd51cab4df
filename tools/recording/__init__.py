"""Recordings: stereocam record, stereocam recording (info, repair, export) and stereocam rematch."""
