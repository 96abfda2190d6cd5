"""Loads an exported MJCF scene in real MuJoCo, simulates one second, and checks that
every free body rests where it was put: moved less than --max-move metres, and no
contact deeper than --max-penetration metres. Prints a JSON summary; exit 1 on failure."""
import argparse, json, sys

import mujoco
import numpy as np

parser = argparse.ArgumentParser()
parser.add_argument("scene")
parser.add_argument("--seconds", type=float, default=1.0)
parser.add_argument("--max-move", type=float, default=0.003)
parser.add_argument("--max-penetration", type=float, default=0.001)
args = parser.parse_args()

model = mujoco.MjModel.from_xml_path(args.scene)
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
bodies = [b for b in range(model.nbody) if model.body_jntnum[b] > 0]
start = {b: data.xpos[b].copy() for b in bodies}
deepest = 0.0
for _ in range(int(args.seconds / model.opt.timestep)):
    mujoco.mj_step(model, data)
    for c in data.contact[: data.ncon]:
        deepest = min(deepest, c.dist)
moves = {model.body(b).name: float(np.linalg.norm(data.xpos[b] - start[b])) for b in bodies}
ok = all(m < args.max_move for m in moves.values()) and -deepest < args.max_penetration
print(json.dumps({"bodies": len(bodies), "moves": moves, "deepest_contact": deepest,
                  "contacts_at_end": int(data.ncon), "ok": ok}))
sys.exit(0 if ok else 1)
