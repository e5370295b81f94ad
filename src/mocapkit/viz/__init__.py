"""Plots, the HTML report and the live web viewer (viser, the ``viz`` extra)."""
