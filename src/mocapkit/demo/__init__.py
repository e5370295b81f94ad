"""The end-to-end demo: a simulated suit through the live chain, a real marker trial,
the orientation filters on a real recording, and the HTML report."""
