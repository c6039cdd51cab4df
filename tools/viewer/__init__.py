"""stereocam view: a live viewer in the browser (an HTTP server on a local port and a static page)."""
