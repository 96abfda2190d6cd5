"""Closes a simulated parallel-jaw gripper at each case's planned grasp in MuJoCo and
lifts 10 cm: the grasp holds when the true object rose at least 8 cm with the hand.
Reads the directories `examples/grasp_lift.rs` writes; prints one JSON line per case and
a summary by grasp kind and by the suite's category.

The hand is a dynamic body on three world-axis slide joints under stiff position
servos, gravity-compensated: its contacts then see its real velocity (a mocap hand
teleports, and friction against it cannot carry the object up). Gravity is off while
the hand comes in and closes (the suite's objects float), then on for the lift and a
hold. Each finger squeezes with `--force-per-kg` times the object's mass (a Franka
Hand's 70 N on 0.2 kg is 350 N/kg); the pads' torsional friction is that of a soft pad
pressed over a quarter of its width (friction x width / 4).

python3 scripts/grasp_lift.py DIR [--friction 0.5] [--force-per-kg 350]"""
import argparse, json, os

import mujoco
import numpy as np

parser = argparse.ArgumentParser()
parser.add_argument("dir")
parser.add_argument("--friction", type=float, default=0.5)
parser.add_argument("--force-per-kg", type=float, default=350.0)
args = parser.parse_args()

LIFT = 0.10
HAND_STIFFNESS = 2e5  # N/m per world axis: a 5 kg object sags the hand by a quarter mm


def fmt(v):
    return " ".join(f"{x:.9f}" for x in v)


def quat_of(rot):
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, dtype=float).reshape(9))
    return q


def hand_xml(g, start, rot, squeeze):
    grasp, gripper = g["grasp"], g["gripper"]
    opening, tip = grasp["pregrasp_opening"], grasp["tip_reach"]
    depth, width, thick = gripper["finger_depth"], gripper["finger_width"], g["finger_thickness"]
    friction = f"{args.friction} {args.friction * width / 4:.6f} 0.0001"
    centre_x = tip - depth / 2
    # the slide joints move the hand along the world's axes: in the hand's frame those
    # are the rows of its rotation
    joints = "".join(
        f'<joint name="hand_{n}" type="slide" axis="{fmt(rot[i])}" damping="3000"/>'
        for i, n in enumerate("xyz"))
    pad = f'friction="{friction}" condim="4"'
    hand = f"""
    <body name="hand" pos="{fmt(start)}" quat="{fmt(quat_of(rot))}" gravcomp="1">
      {joints}
      <geom type="box" size="{thick/2:.6f} {opening/2 + thick:.6f} {width/2:.6f}" pos="{centre_x - depth/2 - thick/2:.6f} 0 0" mass="1" {pad}/>
      <body name="left" pos="{centre_x:.6f} {-(opening/2 + thick/2):.6f} 0" gravcomp="1">
        <joint name="left" type="slide" axis="0 1 0" limited="true" range="0 {opening/2:.6f}" damping="20"/>
        <geom type="box" size="{depth/2:.6f} {thick/2:.6f} {width/2:.6f}" mass="0.2" {pad}/>
      </body>
      <body name="right" pos="{centre_x:.6f} {opening/2 + thick/2:.6f} 0" gravcomp="1">
        <joint name="right" type="slide" axis="0 -1 0" limited="true" range="0 {opening/2:.6f}" damping="20"/>
        <geom type="box" size="{depth/2:.6f} {thick/2:.6f} {width/2:.6f}" mass="0.2" {pad}/>
      </body>
    </body>
"""
    # force-controlled fingers (a stiff position servo on a light finger is unstable at
    # the step that keeps the contacts stiff)
    fingers = "".join(
        f'<motor name="{n}" joint="{n}" ctrllimited="true" ctrlrange="0 {squeeze:.3f}"/>'
        for n in ("left", "right"))
    arm = "".join(f'<position name="hand_{n}" joint="hand_{n}" kp="{HAND_STIFFNESS}"/>' for n in "xyz")
    return hand, arm + fingers


def build(case_dir, g):
    grasp = g["grasp"]
    a = np.array(grasp["approach"])
    pos = np.array(grasp["position"])
    rot = np.array(grasp["rotation"])  # row-major, columns approach, closing, binormal
    start = pos - a * (g["gripper"]["finger_depth"] + 0.02)
    mass = object_mass(case_dir)
    squeeze = args.force_per_kg * max(mass, 0.05)
    hand, actuators = hand_xml(g, start, rot, squeeze)
    xml = open(os.path.join(case_dir, "scene.xml")).read()
    # MuJoCo caches meshes by their file's path: a relative path would give every case
    # the first case's object
    xml = xml.replace('meshdir="."', f'meshdir="{case_dir}"')
    xml = xml.replace("  </worldbody>", hand + "  </worldbody>")
    xml = xml.replace("</mujoco>", f"  <actuator>{actuators}</actuator>\n</mujoco>")
    model = mujoco.MjModel.from_xml_string(xml, {})
    return model, pos - start, mass, squeeze


def object_mass(case_dir):
    model = mujoco.MjModel.from_xml_path(os.path.join(case_dir, "scene.xml"))
    return model.body_subtreemass[model.body("object_0").id]


def simulate(case_dir):
    g = json.load(open(os.path.join(case_dir, "grasp.json")))
    if g["grasp"] is None:
        return {"seed": g["seed"], "kind": "none", "partial": g["partial"],
                "noise": g["noise"], "outliers": g["outliers"],
                "fit_success": g["fit_success"], "why_none": g["why_none"], "held": False}
    model, travel, mass, squeeze = build(case_dir, g)
    obj = model.body("object_0").id
    opening = g["grasp"]["pregrasp_opening"]
    # grasping needs friction that holds: elliptic cones, a high impedance ratio and the
    # no-slip solver (MuJoCo's advice for manipulation)
    model.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    model.opt.impratio = 10
    model.opt.noslip_iterations = 10
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    # stiff contacts: a squeeze of hundreds of newtons must not push the pads centimetres
    # into the object (MuJoCo's default time constant of 0.02 s does), so the step is
    # 1 ms and the contacts' time constant twice that
    model.opt.timestep = 0.001
    for gid in range(model.ngeom):
        if model.geom_bodyid[gid] == obj:
            model.geom_friction[gid] = [args.friction, 0.0, 0.0]
            model.geom_condim[gid] = 4
        model.geom_solref[gid] = [0.002, 1.0]
        model.geom_solimp[gid] = [0.99, 0.999, 0.0005, 0.5, 2.0]
    data = mujoco.MjData(model)
    model.opt.gravity[:] = 0
    mujoco.mj_forward(model, data)
    z0 = data.xpos[obj][2]
    dt = model.opt.timestep
    hand_act = [model.actuator(f"hand_{n}").id for n in "xyz"]
    finger_act = [model.actuator(n).id for n in ("left", "right")]
    lift = np.array([0.0, 0.0, LIFT])
    phases = [(0.5, "approach"), (0.4, "close"), (0.8, "lift"), (0.5, "hold")]
    for duration, phase in phases:
        steps = int(duration / dt)
        for k in range(steps):
            s = (k + 1) / steps
            if phase == "approach":
                data.ctrl[hand_act] = travel * s
            if phase == "close":
                data.ctrl[finger_act] = squeeze * s
            if phase == "lift":
                model.opt.gravity[:] = [0, 0, -9.81]
                data.ctrl[hand_act] = travel + lift * s
            mujoco.mj_step(model, data)
    rise = float(data.xpos[obj][2] - z0)
    return {"seed": g["seed"], "kind": g["grasp"]["kind"], "partial": g["partial"],
            "noise": g["noise"], "outliers": g["outliers"], "fit_success": g["fit_success"],
            "mass": round(float(mass), 3), "rise": round(rise, 4), "held": rise >= 0.8 * LIFT}


def tally(results, key):
    out = {}
    for r in results:
        k = out.setdefault(str(key(r)), [0, 0])
        k[0] += r["held"]
        k[1] += 1
    return out


results = []
root = os.path.abspath(args.dir)
for name in sorted(os.listdir(root)):
    case_dir = os.path.join(root, name)
    if not os.path.exists(os.path.join(case_dir, "grasp.json")):
        continue
    r = simulate(case_dir)
    print(json.dumps(r))
    results.append(r)
print(json.dumps({
    "cases": len(results), "held": sum(r["held"] for r in results),
    "by_kind": tally(results, lambda r: r["kind"]),
    "by_category": tally(results, lambda r: ("view" if r["partial"] else "full")
                         + f" noise {r['noise']}" + (" outliers" if r["outliers"] else "")),
}))
