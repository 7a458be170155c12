"""Definitions every layer shares (pipeline, storage, flows): imports nothing of the project."""
