"""stereocam soak: long fuzz and faulty-link streaming runs, and the faulty link they use."""
