"""Hash every array of short regression flights: python bits.py name... (prints name key sha)."""
import hashlib, sys
from pathlib import Path
import numpy as np
import trn_env
from trn_env.scenario.loading import load_scenario
from trn_env.sim.closed_loop import ClosedLoop
print("trn_env from", trn_env.__file__, file=sys.stderr)
SCEN = Path("/tmp/core-base/tests/scenarios")
for name in sys.argv[1:]:
    res = ClosedLoop(load_scenario(SCEN / f"{name}.toml")).run()
    h = hashlib.sha256()
    for k in sorted(res.arrays):
        v = np.ascontiguousarray(res.arrays[k])
        h.update(k.encode()); h.update(v.tobytes() if v.dtype != object else repr(v.tolist()).encode())
    e = res.arrays["err_ned_m"]
    eh = np.hypot(e[:, 0], e[:, 1])
    print(name, res.termination, h.hexdigest()[:16], "rms_h %.4f final_h %.4f max_h %.4f" % (
        float(np.sqrt(np.mean(eh ** 2))), float(eh[-1]), float(eh.max())), flush=True)
