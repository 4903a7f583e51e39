#!/usr/bin/env node
// Writes a complete Haptify 1.0 session folder from the specification alone (spec chapters 1-4 and
// schemas/1.0/*.json), as a third-party lab would: no Haptify code, no npm packages.
//
//   node spec/examples/write_session.js OUT_DIR
//
// Every value is computed from analytic signals (sines of time), so a reader can check any sample.
// Streams are CSV (spec §3.2): Parquet would need a library. The folder is written into a temporary
// sibling and renamed into place when complete (spec §3.6); an existing OUT_DIR is refused.
"use strict";

const fs = require("fs");
const path = require("path");
const crypto = require("crypto");

// ---------------------------------------------------------------- constants (spec §1.2, §2.3, §2.4)
const G = 9.80665; // standard gravity, m/s^2 (spec §1.2)
const G_W = [0, 0, -G]; // gravity in the world frame W, z up

// The Touch (paper Table II), exactly the DH table of spec §2.3: q3's upper limit depends on q2.
const TOUCH_JOINTS = [
  { name: "q1", a: 0.0, alpha: 1.5707963, d: 0, theta_offset: 0,
    lower: { constant: -0.9774 }, upper: { constant: 0.9774 } },
  { name: "q2", a: 0.135, alpha: 0.0, d: 0, theta_offset: 0,
    lower: { constant: 0.0 }, upper: { constant: 1.7628 } },
  { name: "q3", a: 0.135, alpha: 0.0, d: 0, theta_offset: 0,
    lower: { constant: -2.4435 }, upper: { constant: -0.1745, coefficients: { q2: -0.85 } } },
];
const DH_BASE = { position: [0, 0, 0.06], quaternion: [1, 0, 0, 0] }; // DH base frame in D
const DEVICE_PLACEMENT = { position: [-0.15, 0, 0], quaternion: [1, 0, 0, 0] }; // D in W
const Q_CENTRE = [0.0, 0.7, -1.0]; // joint angles of the workspace centre the examiner moves around

// Handle sensors in the handle body frame H (origin: gimbal centre).
const FT_POSE = { position: [0, 0, -0.03], quaternion: [1, 0, 0, 0] };
const ACC_POSE = { position: [0.01, 0, -0.05], quaternion: [1, 0, 0, 0] };
// Handle gravity calibration (paper eqs. 1-3): the values the raw streams are generated with.
const HG = {
  force_bias_N: [0.12, -0.05, 0.3],
  connector_mass_kg: 0.045,
  connector_com_m: [0.002, -0.001, 0.015],
  torque_bias_Nm: [0.004, 0.002, -0.001],
  accel_bias_m_per_s2: [0.05, -0.03, 0.08],
  gravity_m_per_s2: G,
};
// Motion-capture markers on the handle rigid body, positions in H.
const HANDLE_MARKERS = { h1: [0.02, 0, 0.01], h2: [-0.015, 0.02, 0.012], h3: [0, -0.02, 0.03] };
// Force plate: corner sensors 2.5 cm below the top surface, axes parallel to W (spec §2.4).
const CORNERS = [
  ["c1", [0.25, 0.15, -0.025]], ["c2", [-0.25, 0.15, -0.025]],
  ["c3", [-0.25, -0.15, -0.025]], ["c4", [0.25, -0.15, -0.025]],
];
const PLATE_BIAS = [0.5, -0.3, 1.2, 0.01, -0.02, 0.003]; // per corner, added to every corner's 6 axes
const DEVICE_MASS_KG = 1.6; // load the device puts on the plate (not a datasheet figure)

// The handle's orientation: a fixed tilt about x (an exact Pythagorean unit quaternion, so the first
// sample is exact) then a yaw theta(t) about world z.
const Q_TILT = [0.96, 0.28, 0, 0];

// ---------------------------------------------------------------- small vector/quaternion algebra
const add = (a, b) => a.map((v, i) => v + b[i]);
const sub = (a, b) => a.map((v, i) => v - b[i]);
const scale = (a, s) => a.map((v) => v * s);
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];

// Hamilton product, scalar first (spec §1.3).
function qmul(p, q) {
  const [pw, px, py, pz] = p;
  const [qw, qx, qy, qz] = q;
  return [
    pw * qw - px * qx - py * qy - pz * qz,
    pw * qx + px * qw + py * qz - pz * qy,
    pw * qy - px * qz + py * qw + pz * qx,
    pw * qz + px * qy - py * qx + pz * qw,
  ];
}
// Rotation matrix (rows) of a unit quaternion that rotates body -> parent.
function qmat(q) {
  const [w, x, y, z] = q;
  return [
    [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ];
}
const mv = (m, v) => m.map((r) => r[0] * v[0] + r[1] * v[1] + r[2] * v[2]); // m · v
const mtv = (m, v) => [0, 1, 2].map((j) => m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2]); // mᵀ · v

// ---------------------------------------------------------------- DH forward kinematics (spec §2.3)
function mat4mul(A, B) {
  const C = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]];
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) for (let k = 0; k < 4; k++) C[i][j] += A[i][k] * B[k][j];
  return C;
}
function poseMat4(pose) {
  const R = qmat(pose.quaternion);
  const p = pose.position;
  return [[...R[0], p[0]], [...R[1], p[1]], [...R[2], p[2]], [0, 0, 0, 1]];
}
// T_{i-1,i} = Rot_z(q_i + theta_offset_i) · Trans_z(d_i) · Trans_x(a_i) · Rot_x(alpha_i)
function dhMat4(j, q) {
  const th = q + j.theta_offset;
  const ct = Math.cos(th), st = Math.sin(th), ca = Math.cos(j.alpha), sa = Math.sin(j.alpha);
  return [
    [ct, -st * ca, st * sa, j.a * ct],
    [st, ct * ca, -ct * sa, j.a * st],
    [0, sa, ca, j.d],
    [0, 0, 0, 1],
  ];
}
// A joint limit: constant + Σ slope·q_k over earlier joints.
function limitValue(limit, qByName) {
  let v = limit.constant;
  for (const [k, slope] of Object.entries(limit.coefficients || {})) v += slope * qByName[k];
  return v;
}
// Gimbal centre (the chain's last frame origin) in W for joint angles q (rad); throws outside the limits.
function gimbalCentreW(q) {
  const byName = {};
  TOUCH_JOINTS.forEach((j, i) => { byName[j.name] = q[i]; });
  let T = mat4mul(poseMat4(DEVICE_PLACEMENT), poseMat4(DH_BASE));
  TOUCH_JOINTS.forEach((j, i) => {
    const lo = limitValue(j.lower, byName), hi = limitValue(j.upper, byName);
    if (q[i] < lo || q[i] > hi) throw new Error(`${j.name}=${q[i]} outside [${lo}, ${hi}]`);
    T = mat4mul(T, dhMat4(j, q[i]));
  });
  return [T[0][3], T[1][3], T[2][3]];
}

// ---------------------------------------------------------------- analytic handle motion
const TWO_PI = 2 * Math.PI;
const CENTRE = gimbalCentreW(Q_CENTRE);
// Free space: a slow Lissajous path (below the paper's 0.16 m/s) and a slow yaw (below 16 deg/s).
const AMP = [0.03, 0.02, 0.015], FREQ = [0.25, 0.4, 0.3]; // m, Hz
const YAW_AMP = 0.2, YAW_FREQ = 0.2; // rad, Hz
const VISCOUS = 2.0; // N·s/m: the unpowered device resists motion (force on the hand = −VISCOUS·v)
const VIB_AMP = 0.2, VIB_FREQ = 150; // m/s^2, Hz: a vibration along the accelerometer's x axis

function freeSpaceMotion(tau) {
  const w = FREQ.map((f) => TWO_PI * f);
  const p = CENTRE.map((c, i) => c + AMP[i] * Math.sin(w[i] * tau));
  const v = AMP.map((a, i) => a * w[i] * Math.cos(w[i] * tau));
  const acc = AMP.map((a, i) => -a * w[i] * w[i] * Math.sin(w[i] * tau));
  const W = TWO_PI * YAW_FREQ;
  const th = YAW_AMP * Math.sin(W * tau);
  const thd = YAW_AMP * W * Math.cos(W * tau);
  const thdd = -YAW_AMP * W * W * Math.sin(W * tau);
  const q = qmul([Math.cos(th / 2), 0, 0, Math.sin(th / 2)], Q_TILT);
  return { p, v, acc, q, th, thd, thdd };
}

// Raw specific force of the accelerometer in its frame A: b_a + R_WA^T (a_A − g_W) (spec §1.5).
function accelReading(m, tau) {
  const R = qmat(m.q);
  const rW = mv(R, ACC_POSE.position); // accelerometer offset from the gimbal centre, in W
  // rotation about world z only: r̈ = θ̈ (ẑ × r) + θ̇² ẑ × (ẑ × r)
  const zr = [-rW[1], rW[0], 0];
  const zzr = [-rW[0], -rW[1], 0];
  const aA = add(m.acc, add(scale(zr, m.thdd), scale(zzr, m.thd * m.thd)));
  const RA = mat3mul(R, qmat(ACC_POSE.quaternion));
  const f = add(HG.accel_bias_m_per_s2, mtv(RA, sub(aA, G_W)));
  f[0] += VIB_AMP * Math.sin(TWO_PI * VIB_FREQ * tau);
  return f;
}
function mat3mul(A, B) {
  return A.map((r) => [0, 1, 2].map((j) => r[0] * B[0][j] + r[1] * B[1][j] + r[2] * B[2][j]));
}
// Raw F/T reading in the sensor frame S (paper eq. 1 plus the device's force on the hand F_W):
// F_S = b_F + R_WS^T (m g_W + F_W);  τ_S = b_τ + c × (m R_WS^T g_W) + r_gS × (R_WS^T F_W),
// r_gS = the gimbal centre (where the device's force acts) in S.
function ftReading(q, forceW) {
  const RS = mat3mul(qmat(q), qmat(FT_POSE.quaternion));
  const weightS = mtv(RS, scale(G_W, HG.connector_mass_kg));
  const devS = mtv(RS, forceW);
  const rgS = mtv(qmat(FT_POSE.quaternion), scale(FT_POSE.position, -1));
  const F = add(HG.force_bias_N, add(weightS, devS));
  const T = add(HG.torque_bias_Nm, add(cross(HG.connector_com_m, weightS), cross(rgS, devS)));
  return F.concat(T);
}
// Raw corner readings: the device's weight plus the reaction to its force on the hand, split over the
// corners by the bilinear lever rule about the device base; each corner reports the force the plate
// applies to it (compression reads negative fz), torques zero, plus the corner bias.
function plateReading(forceOnHandW) {
  const base = DEVICE_PLACEMENT.position;
  const load = sub([0, 0, -DEVICE_MASS_KG * G], forceOnHandW); // force the device applies to the plate
  const out = [];
  const [sx, sy] = [0.5, 0.3];
  for (const [, pos] of CORNERS) {
    const wx = 0.5 + ((pos[0] > 0 ? 1 : -1) * base[0]) / sx;
    const wy = 0.5 + ((pos[1] > 0 ? 1 : -1) * base[1]) / sy;
    const share = wx * wy;
    for (let k = 0; k < 3; k++) out.push(PLATE_BIAS[k] + share * load[k]);
    for (let k = 3; k < 6; k++) out.push(PLATE_BIAS[k]);
  }
  return out;
}

// ---------------------------------------------------------------- stream writing (spec §2.6, §3.2, §3.4)
const KINDS = JSON.parse(fs.readFileSync(path.join(__dirname, "..", "..", "schemas", "1.0", "stream-kinds.json"), "utf8")).kinds;
const FRAMES = { handle_wrench: "handle_ft_sensor", handle_accel: "handle_accelerometer",
  plate_wrench: "plate_corner_sensors", handle_pose: "world", markers: "world", commanded_wrench: "world" };

// The declared columns of a kind: t (s) first, then the kind's columns, per entity for markers/link_poses.
function kindColumns(kind, entities) {
  const k = KINDS[kind];
  const cols = [{ name: "t", unit: "s" }];
  if (k.entity_columns) {
    for (const e of entities) for (const c of k.entity_columns) cols.push({ name: `${e}_${c.name}`, unit: c.unit });
  } else {
    for (const c of k.columns) cols.push({ name: c.name, unit: c.unit });
  }
  return cols;
}
// JavaScript's Number → string is the shortest representation that round-trips (spec §3.2), except
// that it prints −0 as "0"; NaN → "NaN" as the spec requires. Infinities are never allowed (E210).
const num = (x) => {
  if (!Number.isNaN(x) && !Number.isFinite(x)) throw new Error(`infinite value ${x}`);
  return Object.is(x, -0) ? "-0" : String(x);
};

/** Write one CSV stream of `n` samples at `rate` Hz starting at t0 (s); rowFn(i, t, tau) → values. */
function writeStream(root, trialId, kind, { rate, n, t0, entities }, rowFn) {
  const columns = kindColumns(kind, entities || []);
  const rel = `trials/${trialId}/${kind}.csv`;
  const lines = [columns.map((c) => c.name).join(",")];
  for (let i = 0; i < n; i++) {
    const tau = i / rate;
    const t = t0 + tau;
    const values = rowFn(i, t, tau);
    if (values.length !== columns.length - 1) throw new Error(`${kind}: ${values.length} values`);
    lines.push([t, ...values].map(num).join(","));
  }
  const bytes = Buffer.from(lines.join("\n") + "\n", "utf8");
  fs.mkdirSync(path.join(root, "trials", trialId), { recursive: true });
  fs.writeFileSync(path.join(root, rel), bytes);
  const stream = { kind, file: rel, format: "csv", rate_hz: rate, frame: FRAMES[kind], columns, rows: n,
    sha256: crypto.createHash("sha256").update(bytes).digest("hex") };
  if (entities) stream.entities = entities;
  return stream;
}

// ---------------------------------------------------------------- the trials
const NAN7 = [NaN, NaN, NaN, NaN, NaN, NaN, NaN];
const POSE_GAP = [120, 135]; // handle_pose rows [120, 135) are occluded (5 % of 300)
const MARKER_GAP = [40, 50]; // marker h2 rows [40, 50) are occluded

function freeSpaceTrial(root) {
  const id = "free_space-1", t0 = 10.0, T = 3.0;
  const forceOnHand = (m) => scale(m.v, -VISCOUS);
  const streams = [
    writeStream(root, id, "handle_wrench", { rate: 1000, n: T * 1000, t0 }, (i, t, tau) => {
      const m = freeSpaceMotion(tau);
      return ftReading(m.q, forceOnHand(m));
    }),
    writeStream(root, id, "handle_accel", { rate: 2000, n: T * 2000, t0 }, (i, t, tau) =>
      accelReading(freeSpaceMotion(tau), tau)),
    writeStream(root, id, "handle_pose", { rate: 100, n: T * 100, t0 }, (i, t, tau) => {
      if (i >= POSE_GAP[0] && i < POSE_GAP[1]) return NAN7;
      const m = freeSpaceMotion(tau);
      return m.p.concat(m.q);
    }),
    writeStream(root, id, "markers", { rate: 100, n: T * 100, t0, entities: ["h1", "h2"] }, (i, t, tau) => {
      const m = freeSpaceMotion(tau);
      const R = qmat(m.q);
      const h1 = add(m.p, mv(R, HANDLE_MARKERS.h1));
      const h2 = i >= MARKER_GAP[0] && i < MARKER_GAP[1] ? [NaN, NaN, NaN] : add(m.p, mv(R, HANDLE_MARKERS.h2));
      return h1.concat(h2);
    }),
    writeStream(root, id, "plate_wrench", { rate: 1000, n: T * 1000, t0 }, (i, t, tau) =>
      plateReading(forceOnHand(freeSpaceMotion(tau)))),
  ];
  return { id, protocol: "free_space", repetition: 1, powered: false,
    notes: "Analytic free-space wandering around the Touch's workspace centre.", streams };
}

const K_RENDER = 750; // N/m, the paper's commanded stiffness
const TRACKING = 0.92; // the device delivers 92 % of the commanded force
function stiffnessTrial(root) {
  const id = "stiffness-1", t0 = 20.0, T = 4.0;
  const surfaceZ = CENTRE[2];
  // Two presses per second down to 4 mm below the surface, from 5 mm above it.
  const z = (tau) => surfaceZ + 0.005 - 0.009 * (1 - Math.cos(TWO_PI * 0.5 * tau)) / 2;
  const cmd = (tau) => [0, 0, K_RENDER * Math.max(0, surfaceZ - z(tau)), 0, 0, 0];
  const streams = [
    writeStream(root, id, "handle_wrench", { rate: 1000, n: T * 1000, t0 }, (i, t, tau) =>
      ftReading(Q_TILT, scale(cmd(tau).slice(0, 3), TRACKING))),
    writeStream(root, id, "handle_pose", { rate: 100, n: T * 100, t0 }, (i, t, tau) =>
      [CENTRE[0], CENTRE[1], z(tau)].concat(Q_TILT)),
    writeStream(root, id, "commanded_wrench", { rate: 1000, n: T * 1000, t0 }, (i, t, tau) => cmd(tau)),
  ];
  return { id, protocol: "stiffness", repetition: 1, powered: true,
    rendering: { surface_point_m: [CENTRE[0], CENTRE[1], surfaceZ], surface_normal: [0, 0, 1],
      stiffness_N_per_m: K_RENDER, static_friction: 0, dynamic_friction: 0,
      software: "CHAI3D 3.2", loop_rate_hz: 1000 },
    streams };
}

// ---------------------------------------------------------------- the manifest (spec §2.1)
function buildSession(root) {
  const range = (f, t) => ({ force_N: f, torque_Nm: t });
  return {
    spec_version: "1.0",
    session_id: "js-example-0001",
    date: "2026-11-22",
    lab: { id: "lab-js-example" },
    examiner: { id: "ex-01" },
    device: {
      manufacturer: "3D Systems", model: "Touch", serial: "TOUCH-EXAMPLE-1", dof: 6, mechanism: "hybrid",
      kinematics: { convention: "dh_standard", base: DH_BASE, joints: TOUCH_JOINTS },
      gimbal: { dof: 3, tip_offset_m: 0.039 },
      datasheet: { workspace_box_m: [0.16, 0.12, 0.07], peak_force_N: 3.3, friction_N: 0.26,
        source: "paper Table II" },
    },
    device_placement: DEVICE_PLACEMENT,
    rig: {
      name: "JS example rig (paper Table I ranges)",
      force_plate: { size_m: [0.6, 0.4],
        corners: CORNERS.map(([cid, pos]) => ({ id: cid, pose: { position: pos, quaternion: [1, 0, 0, 0] } })),
        corner_range: range([200, 200, 400], [10, 10, 10]) },
      handle: {
        ft_sensor: { pose: FT_POSE, range: range([70, 70, 190], [5, 5, 5]), model: "ATI Mini27 Titanium" },
        accelerometer: { pose: ACC_POSE, range: { accel_m_per_s2: [40, 40, 40] }, model: "MPU-9250" },
      },
      motion_capture: { system: "Vicon", rate_hz: 100, markers: Object.keys(HANDLE_MARKERS),
        rigid_bodies: [{ name: "handle", markers: Object.keys(HANDLE_MARKERS) }] },
    },
    calibration: [{ kind: "handle_gravity", id: "handle-gravity-1", ...HG }],
    trials: [freeSpaceTrial(root), stiffnessTrial(root)],
    recorder: "spec/examples/write_session.js (Haptify 1.0 third-party example)",
  };
}

function main(argv) {
  if (argv.length !== 1 || argv[0].startsWith("-")) {
    process.stderr.write("usage: node write_session.js OUT_DIR\n");
    return 2;
  }
  const out = path.resolve(argv[0]);
  if (fs.existsSync(out)) {
    process.stderr.write(`error: ${out} exists; choose another output folder\n`);
    return 1;
  }
  const tmp = path.join(path.dirname(out), `.${path.basename(out)}.tmp-${process.pid}`);
  try {
    fs.mkdirSync(tmp, { recursive: false });
    const session = buildSession(tmp);
    fs.writeFileSync(path.join(tmp, "session.json"), JSON.stringify(session, null, 1) + "\n");
    fs.renameSync(tmp, out); // the session appears complete or not at all (spec §3.6)
  } catch (err) {
    fs.rmSync(tmp, { recursive: true, force: true });
    process.stderr.write(`error: ${err.message}\n`);
    return 1;
  }
  process.stdout.write(`wrote ${out}\n`);
  return 0;
}

if (require.main === module) process.exitCode = main(process.argv.slice(2));
