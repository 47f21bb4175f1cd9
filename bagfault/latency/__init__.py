"""Path latency from bag data, with CARET architecture files."""
