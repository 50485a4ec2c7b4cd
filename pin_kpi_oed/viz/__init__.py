"""Visualisation at the edge: meshcat scene, static HTML, matplotlib figures."""
