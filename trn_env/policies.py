"""`trn_env.policies`: the route policies of the env stage (trn_env/env/policies.py), re-exported."""

from trn_env.env.policies import PlannerPolicy, StraightLinePolicy

__all__ = ["PlannerPolicy", "StraightLinePolicy"]
