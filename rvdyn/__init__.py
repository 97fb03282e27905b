"""rvdyn package."""
