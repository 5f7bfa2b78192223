"""Verdicts: the metrics, statistical tests and tolerances that judge two images
(compare)."""
