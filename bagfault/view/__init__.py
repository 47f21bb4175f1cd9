"""Views of a run while it happens: a Foxglove WebSocket server (`--foxglove`)."""
