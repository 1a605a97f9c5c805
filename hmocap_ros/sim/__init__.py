"""Synthetic smart room: body motion, cameras, rendering, MCAP bags with ground truth."""
