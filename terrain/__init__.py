"""Terrain: DEMs, map error models, terrain queries and metrics. Imports neither trn_env nor navigators."""
