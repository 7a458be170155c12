"""The `jitroute` command line: the top layer. It parses, prints and calls flows (or pipeline for quick work)."""
