"""rvstudy package."""
