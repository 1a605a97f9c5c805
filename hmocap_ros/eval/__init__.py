"""Offline evaluation: metrics and runners over bags."""
