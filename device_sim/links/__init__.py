"""How a simulated unit meets a host: in-process pipe (``sim://``), pty and TCP servers, USB."""
