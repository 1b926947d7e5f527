"""Navigators: estimators that run on sensor frames. They never import trn_env or JSBSim."""
