"""trn-env: a closed-loop test range for terrain-referenced navigation."""

__version__ = "0.1.0"
