"""Plots, reports and viewers (matplotlib figures; the live viewer lives elsewhere)."""
