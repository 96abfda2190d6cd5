"""Closes a simulated parallel-jaw gripper at each case's planned grasp in MuJoCo and
lifts 10 cm: the grasp holds when the true object rose at least 8 cm with the hand.
Reads the directories `examples/grasp_lift.rs` writes; prints one JSON line per case and
a summary. Gravity is off while the hand comes in and closes (the suite's objects float),
then on for the lift and a hold. The pads' torsional friction is that of a soft pad
pressed over a quarter of its width (friction x width / 4).

python3 scripts/grasp_lift.py DIR [--friction 0.5] [--force-per-kg 350]"""
import argparse, json, os, sys

import mujoco
import numpy as np

parser = argparse.ArgumentParser()
parser.add_argument("dir")
parser.add_argument("--friction", type=float, default=0.5)
parser.add_argument("--force-per-kg", type=float, default=350.0)
args = parser.parse_args()


def fmt(v):
    return " ".join(f"{x:.9f}" for x in v)


def quat_of(rot):
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, dtype=float).reshape(9))
    return q


def run(case_dir):
    g = json.load(open(os.path.join(case_dir, "grasp.json")))
    grasp, gripper = g["grasp"], g["gripper"]
    a = np.array(grasp["approach"])
    pos = np.array(grasp["position"])
    rot = np.array(grasp["rotation"])  # row-major, columns approach, closing, binormal
    opening, tip = grasp["pregrasp_opening"], grasp["tip_reach"]
    depth, width, thick = gripper["finger_depth"], gripper["finger_width"], g["finger_thickness"]
    xml = open(os.path.join(case_dir, "scene.xml")).read()
    friction = f"{args.friction} {args.friction * width / 4:.6f} 0.0001"
    centre_x = tip - depth / 2
    standoff = depth + 0.02
    start = pos - a * standoff
    hand = f"""
    <body name="hand" mocap="true" pos="{fmt(start)}" quat="{fmt(quat_of(rot))}">
      <geom type="box" size="{thick/2:.6f} {opening/2 + thick:.6f} {width/2:.6f}" pos="{centre_x - depth/2 - thick/2:.6f} 0 0" friction="{friction}"/>
      <body name="left" pos="{centre_x:.6f} {-(opening/2 + thick/2):.6f} 0">
        <joint name="left" type="slide" axis="0 1 0" limited="true" range="0 {opening/2:.6f}" damping="20"/>
        <geom type="box" size="{depth/2:.6f} {thick/2:.6f} {width/2:.6f}" mass="0.2" friction="{friction}" condim="4" solref="0.004 1" solimp="0.95 0.99 0.001"/>
      </body>
      <body name="right" pos="{centre_x:.6f} {opening/2 + thick/2:.6f} 0">
        <joint name="right" type="slide" axis="0 -1 0" limited="true" range="0 {opening/2:.6f}" damping="20"/>
        <geom type="box" size="{depth/2:.6f} {thick/2:.6f} {width/2:.6f}" mass="0.2" friction="{friction}" condim="4" solref="0.004 1" solimp="0.95 0.99 0.001"/>
      </body>
    </body>
"""
    # position-controlled fingers whose force saturates at the squeeze force: at 5 mm
    # short of its target a finger pushes with all of it
    squeeze = g["squeeze"]
    kp = squeeze / 0.005
    actuators = "".join(
        f'<position name="{n}" joint="{n}" kp="{kp:.3f}" forcelimited="true" forcerange="-{squeeze:.3f} {squeeze:.3f}"/>'
        for n in ("left", "right"))
    xml = xml.replace("  </worldbody>", hand + "  </worldbody>")
    xml = xml.replace("</mujoco>", f"  <actuator>{actuators}</actuator>\n</mujoco>")
    model = mujoco.MjModel.from_xml_string(xml, {})
    return model, start, pos, a


def object_mass(case_dir):
    model = mujoco.MjModel.from_xml_path(os.path.join(case_dir, "scene.xml"))
    return model.body_subtreemass[model.body("object_0").id]


def simulate(case_dir):
    g = json.load(open(os.path.join(case_dir, "grasp.json")))
    os.chdir(case_dir)  # the scene's meshes are beside it
    # each finger squeezes with this force (a Franka Hand's 70 N on a 0.2 kg object is
    # 350 N/kg)
    g["squeeze"] = args.force_per_kg * max(object_mass(case_dir), 0.05)
    with open("grasp.json", "w") as f:
        json.dump(g, f)
    model, start, pos, a = run(case_dir)
    obj = model.body("object_0").id
    opening = g["grasp"]["pregrasp_opening"]
    # grasping needs friction that holds: elliptic cones, a high impedance ratio and the
    # no-slip solver (MuJoCo's advice for manipulation)
    model.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    model.opt.impratio = 10
    model.opt.noslip_iterations = 10
    data = mujoco.MjData(model)
    model.opt.gravity[:] = 0
    # the object's own collision geoms get the same friction
    for gid in range(model.ngeom):
        if model.geom_bodyid[gid] == obj:
            model.geom_friction[gid] = [args.friction, 0.0, 0.0]
            model.geom_condim[gid] = 4
    mujoco.mj_forward(model, data)
    z0 = data.xpos[obj].copy()
    dt = model.opt.timestep
    lift = np.array([0.0, 0.0, 0.10])
    phases = [(0.4, "approach"), (0.4, "close"), (0.6, "lift"), (0.5, "hold")]
    for duration, phase in phases:
        steps = int(duration / dt)
        for k in range(steps):
            s = (k + 1) / steps
            if phase == "approach":
                data.mocap_pos[0] = start + (pos - start) * s
            if phase == "close":
                data.ctrl[:] = opening / 2 * s
            if phase == "lift":
                model.opt.gravity[:] = [0, 0, -9.81]
                data.mocap_pos[0] = pos + lift * s
            mujoco.mj_step(model, data)
    rise = float(data.xpos[obj][2] - z0[2])
    return {"seed": g["seed"], "kind": g["grasp"]["kind"], "partial": g["partial"], "noise": g["noise"],
            "fit_success": g["fit_success"], "rise": rise, "held": rise >= 0.08}


results = []
root = os.path.abspath(args.dir)
for name in sorted(os.listdir(root)):
    case_dir = os.path.join(root, name)
    if not os.path.exists(os.path.join(case_dir, "grasp.json")):
        continue
    r = simulate(case_dir)
    print(json.dumps(r))
    results.append(r)
held = sum(r["held"] for r in results)
by_kind = {}
for r in results:
    k = by_kind.setdefault(r["kind"], [0, 0])
    k[0] += r["held"]
    k[1] += 1
print(json.dumps({"cases": len(results), "held": held, "by_kind": by_kind}))
