"""rvcalib package."""
