"""Camera commands (list, info, capture) and what other tools share: sessions, output folders, pictures."""
