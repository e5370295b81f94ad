"""Plots, the HTML report, marker-reconstruction figures and the live web viewer (viser, the
``viz`` extra)."""
