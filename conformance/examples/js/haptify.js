#!/usr/bin/env node
// A small Haptify implementation in JavaScript (Node.js, no packages): proof that the conformance
// protocol is language-neutral (spec §16.4). It speaks the JSON-lines protocol on stdin/stdout and
// computes, from the session manifest and CSV streams only:
//   workspace.spec_box_volume                (spec §8.6)
//   vibration.rms, vibration.spectral_centroid,
//   vibration.baseline_rms, vibration.baseline_centroid   (spec §10.2–10.6)
//   free_space.force_mean                    (spec §9, with chapters 6–7), and with the case parameter
//                                            {"uncertainty": true} its Type A uncertainty (spec §19.2, §19.4)
// Everything else is answered "skipped". Parameters come from schemas/1.0/metrics/*.json and
// schemas/1.0/uncertainty.json.
"use strict";
const fs = require("fs");
const path = require("path");
const readline = require("readline");

const REPO = path.resolve(__dirname, "..", "..", "..");
const PROTOCOL = 1;
const IMPLEMENTATION = { name: "haptify-js-example", version: "0.1.0" };

function readSchema(...parts) {
  return JSON.parse(fs.readFileSync(path.join(REPO, "schemas", "1.0", ...parts), "utf8"));
}

function definition(family) {
  const doc = JSON.parse(fs.readFileSync(path.join(REPO, "schemas", "1.0", "metrics", `${family}.json`), "utf8"));
  const param = (key) => doc.parameters[key].value;
  const unit = (id) => doc.metrics.find((m) => m.id === id).unit;
  return { param, unit, version: doc.version };
}

class Rejected extends Error {
  constructor(code, message) { super(message); this.code = code; }
}

function readManifest(session) {
  const file = path.join(session, "session.json");
  if (!fs.existsSync(file)) throw new Rejected("E101", `no session.json in ${session}`);
  try { return JSON.parse(fs.readFileSync(file, "utf8")); } catch (e) { throw new Rejected("E102", e.message); }
}

function readCsv(session, stream) {
  if (stream.format !== "csv") throw new Error(`only CSV streams are read here, not ${stream.format}`);
  const lines = fs.readFileSync(path.join(session, stream.file), "utf8").split(/\r?\n/).filter((l) => l.length);
  const header = lines[0].split(",");
  const cols = header.map(() => new Float64Array(lines.length - 1));
  for (let r = 1; r < lines.length; r++) {
    const cells = lines[r].split(",");
    for (let c = 0; c < header.length; c++) cols[c][r - 1] = Number(cells[c]);
  }
  return Object.fromEntries(header.map((h, c) => [h, cols[c]]));
}

// --- workspace.spec_box_volume (spec §8.6) ---------------------------------------------------------
function specBoxVolume(manifest) {
  const box = manifest.device && manifest.device.datasheet && manifest.device.datasheet.workspace_box_m;
  if (!box) return null;
  return box.reduce((a, b) => a * b, 1);
}

// --- filters ---------------------------------------------------------------------------------------
// Butterworth low-pass as scipy.signal.butter(order, fc, "low", fs, output="sos"): analog prototype poles
// scaled to the pre-warped cut-off, bilinear transform, double zero at z = −1; each biquad has unit DC gain.
function butterLowpassSos(order, fc, fs) {
  const warped = 2 * fs * Math.tan(Math.PI * fc / fs);
  const sos = [];
  for (let k = 0; k < order / 2; k++) {
    const theta = Math.PI * (2 * k + order + 1) / (2 * order);
    const [sr, si] = [warped * Math.cos(theta), warped * Math.sin(theta)];  // low-pass pole wo·p
    const c = 2 * fs;
    const dr = c - sr, di = -si, nr = c + sr, ni = si;
    const d2 = dr * dr + di * di;
    const zr = (nr * dr + ni * di) / d2, zi = (ni * dr - nr * di) / d2;
    const a1 = -2 * zr, a2 = zr * zr + zi * zi;
    const g = (1 + a1 + a2) / 4;                                      // unit gain at DC (z = 1): |1 + 2 + 1| = 4
    sos.push([g, 2 * g, g, 1, a1, a2]);
  }
  return sos;
}

// scipy.signal.sosfilt_zi: each section's state at rest under a unit step, scaled by the DC gain before it.
function sosfiltZi(sos) {
  let scale = 1;
  return sos.map(([b0, b1, b2, , a1, a2]) => {
    const gain = (b0 + b1 + b2) / (1 + a1 + a2);
    const z2 = b2 - a2 * gain, z1 = b1 + b2 - (a1 + a2) * gain;
    const zi = [scale * z1, scale * z2];
    scale *= gain;
    return zi;
  });
}

// Direct-form II transposed biquads in cascade; ``zi`` (per section) the initial state, or zero.
function sosfiltState(sos, x, zi) {
  let y = Float64Array.from(x);
  sos.forEach(([b0, b1, b2, , a1, a2], s) => {
    let [z1, z2] = zi ? zi[s] : [0, 0];
    const out = new Float64Array(y.length);
    for (let n = 0; n < y.length; n++) {
      const v = y[n];
      const w = b0 * v + z1;
      z1 = b1 * v - a1 * w + z2;
      z2 = b2 * v - a2 * w;
      out[n] = w;
    }
    y = out;
  });
  return y;
}

// scipy.signal.sosfiltfilt(sos, x, padtype="odd", padlen): odd extension, then forward and backward
// passes each started from sosfilt_zi scaled by the pass's first sample.
function sosfiltfiltZi(sos, x, padlen) {
  const n = x.length, ext = new Float64Array(n + 2 * padlen);
  for (let i = 0; i < padlen; i++) {
    ext[i] = 2 * x[0] - x[padlen - i];
    ext[n + padlen + i] = 2 * x[n - 1] - x[n - 2 - i];
  }
  ext.set(x, padlen);
  const zi = sosfiltZi(sos);
  const scaled = (v) => zi.map(([a, b]) => [a * v, b * v]);
  let y = sosfiltState(sos, ext, scaled(ext[0])).reverse();
  y = sosfiltState(sos, y, scaled(y[0])).reverse();
  return y.subarray(padlen, padlen + n);
}

const nominalRate = (t) => (t.length - 1) / (t[t.length - 1] - t[0]);

// Zero-phase low-pass of spec §7.2: the cut-off limited to max_cutoff_fraction of each Nyquist frequency,
// the chord from the first to the last sample removed before filtering and added back after.
function lowpass(x, rate, cutoff, sig) {
  const n = x.length;
  const sos = butterLowpassSos(sig.param("filter_order"), cutoff, rate);
  const chord = (i) => x[0] + (n > 1 ? i / (n - 1) : 0) * (x[n - 1] - x[0]);
  const y = sosfiltfiltZi(sos, x.map((v, i) => v - chord(i)), Math.min(3 * (2 * sos.length + 1), n - 1));
  return y.map((v, i) => v + chord(i));
}

// Linear interpolation at ``tq`` (values beyond the ends held), as numpy.interp; ``t`` increasing.
function interp(t, x, tq) {
  const out = new Float64Array(tq.length);
  let k = 0;
  for (let i = 0; i < tq.length; i++) {
    const q = tq[i];
    if (q <= t[0]) { out[i] = x[0]; continue; }
    if (q >= t[t.length - 1]) { out[i] = x[x.length - 1]; continue; }
    while (t[k + 1] < q) k++;
    out[i] = x[k] + (q - t[k]) / (t[k + 1] - t[k]) * (x[k + 1] - x[k]);
  }
  return out;
}

// --- vibration (spec §10) ----------------------------------------------------------------------------
// Butterworth high-pass as scipy.signal.butter(order, fc, "highpass", fs): analog prototype poles,
// high-pass transform at the pre-warped frequency, bilinear transform; one biquad per conjugate pair.
function butterHighpassSos(order, fc, fs) {
  const warped = 2 * fs * Math.tan(Math.PI * fc / fs);
  const sos = [];
  for (let k = 0; k < order / 2; k++) {
    const theta = Math.PI * (2 * k + order + 1) / (2 * order);        // prototype pole exp(iθ), left half-plane
    const [pr, pi] = [Math.cos(theta), Math.sin(theta)];
    const mag2 = pr * pr + pi * pi;
    const [hr, hi] = [warped * pr / mag2, -warped * pi / mag2];        // high-pass pole wo / p
    const c = 2 * fs;                                                 // bilinear: z = (c + s) / (c - s)
    const dr = c - hr, di = -hi, nr = c + hr, ni = hi;
    const d2 = dr * dr + di * di;
    const zr = (nr * dr + ni * di) / d2, zi = (ni * dr - nr * di) / d2;
    const a1 = -2 * zr, a2 = zr * zr + zi * zi;
    const g = (1 - a1 + a2) / 4;                                      // unit gain at Nyquist (z = −1): |1 + 2 + 1| = 4
    sos.push([g, -2 * g, g, 1, a1, a2]);
  }
  return sos;
}

// Forward and backward with odd extension (scipy sosfiltfilt's default padding); zero initial state —
// the start-up transient has decayed long before the edge_trim_s that is cut afterwards.
function sosfiltfilt(sos, x) {
  const pad = Math.min(3 * (2 * sos.length + 1), x.length - 1);
  const n = x.length, ext = new Float64Array(n + 2 * pad);
  for (let i = 0; i < pad; i++) {
    ext[i] = 2 * x[0] - x[pad - i];
    ext[n + pad + i] = 2 * x[n - 1] - x[n - 2 - i];
  }
  ext.set(x, pad);
  let y = sosfiltState(sos, ext, null).reverse();
  y = sosfiltState(sos, y, null).reverse();
  return y.subarray(pad, pad + n);
}

// Power of the one-sided periodogram per bin (rectangular window, DFT length N; weights 1 at DC and
// Nyquist, 2 elsewhere), by a direct DFT with a twiddle table.
function onesidedPower(x) {
  const n = x.length, half = Math.floor(n / 2);
  const cos = new Float64Array(n), sin = new Float64Array(n);
  for (let m = 0; m < n; m++) { cos[m] = Math.cos(2 * Math.PI * m / n); sin[m] = Math.sin(2 * Math.PI * m / n); }
  const p = new Float64Array(half + 1);
  for (let k = 0; k <= half; k++) {
    let re = 0, im = 0, idx = 0;
    for (let j = 0; j < n; j++) { re += x[j] * cos[idx]; im -= x[j] * sin[idx]; idx += k; if (idx >= n) idx -= n; }
    const w = (k === 0 || (n % 2 === 0 && k === half)) ? 1 : 2;
    p[k] = w * (re * re + im * im);
  }
  return p;
}

function trialVibration(session, trial, def) {
  const stream = trial.streams.find((s) => s.kind === "handle_accel");
  const data = readCsv(session, stream);
  const t = data.t, n = t.length;
  const rate = (n - 1) / (t[n - 1] - t[0]);
  const trim = Math.round(def.param("edge_trim_s") * rate);
  const sos = butterHighpassSos(def.param("highpass_order"), def.param("highpass_cutoff_hz"), rate);
  const kept = n - 2 * trim;
  let energy = 0;
  let power = null;
  for (const axis of ["ax", "ay", "az"]) {
    const x = data[axis];
    const mean = x.reduce((a, b) => a + b, 0) / n;
    const f = sosfiltfilt(sos, x.map((v) => v - mean)).subarray(trim, n - trim);
    for (const v of f) energy += v * v;                                // DFT321 keeps the energy of the three axes
    const p = onesidedPower(f);                                       // and their summed power spectrum
    power = power ? power.map((v, k) => v + p[k]) : p;
  }
  let num = 0, den = 0;
  power.forEach((pk, k) => { num += (k * rate / kept) * pk; den += pk; });
  return { rms: Math.sqrt(energy / kept), centroid: num / den };
}

// --- free_space.force_mean (spec §9.2 with §6.5 and §7.2–7.5) ------------------------------------------
const STANDARD_GRAVITY = 9.80665;

function quatRotate([w, x, y, z], [vx, vy, vz]) {                    // v' = q v q*
  const tx = 2 * (y * vz - z * vy), ty = 2 * (z * vx - x * vz), tz = 2 * (x * vy - y * vx);
  return [vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx)];
}
const quatConj = ([w, x, y, z]) => [w, -x, -y, -z];

function slerp(a, b, s) {
  let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  if (dot < 0) { b = b.map((v) => -v); dot = -dot; }
  if (dot > 0.9995) {
    const q = a.map((v, i) => v + s * (b[i] - v));
    const nrm = Math.hypot(...q);
    return q.map((v) => v / nrm);
  }
  const th = Math.acos(dot), sn = Math.sin(th);
  const wa = Math.sin((1 - s) * th) / sn, wb = Math.sin(s * th) / sn;
  return a.map((v, i) => wa * v + wb * b[i]);
}

// The session's handle calibration: its handle_gravity record (spec §6.4); the calibration trial's fit is
// not implemented here.
function handleGravity(manifest) {
  const rec = (manifest.calibration || []).find((c) => c.kind === "handle_gravity");
  if (!rec) throw new Error("no handle_gravity record (fitting a rig.handle_calibration trial is not implemented here)");
  return rec;
}

// Mean |F| of one trial: the wrench low-passed at its own rate and resampled on the grid at the signals'
// rate_hz spanning all handle streams, the orientation slerped from motion capture, then
// F_W = R_WH R_HS (raw − b_F − m g_S) with g_S the gravity (0, 0, −g₀) in the sensor frame (§6.5).
function trialForceMean(session, manifest, trial, sig) {
  const byKind = (k) => trial.streams.find((s) => s.kind === k);
  if (!byKind("handle_wrench") || !byKind("handle_pose")) throw new Error(`trial ${trial.id} lacks handle_wrench or handle_pose`);
  const data = Object.fromEntries(["handle_pose", "handle_wrench", "handle_accel"].filter(byKind).map((k) => [k, readCsv(session, byKind(k))]));
  const t0 = Math.max(...Object.values(data).map((d) => d.t[0]));
  const t1 = Math.min(...Object.values(data).map((d) => d.t[d.t.length - 1]));
  const rate = sig.param("rate_hz");
  const n = Math.floor((t1 - t0) * rate + 1e-9) + 1;
  const grid = Float64Array.from({ length: n }, (_, k) => t0 + k / rate);
  const w = data.handle_wrench;
  const wrate = nominalRate(w.t);
  const frac = sig.param("max_cutoff_fraction");
  const fc = Math.min(sig.param("wrench_cutoff_hz"), frac * wrate / 2, frac * rate / 2);
  const raw = ["fx", "fy", "fz"].map((c) => interp(w.t, lowpass(w[c], wrate, fc, sig), grid));
  const pose = data.handle_pose;
  const quats = Array.from(pose.t, (_, i) => ["qw", "qx", "qy", "qz"].map((c) => pose[c][i]));
  if (quats.some((q) => q.some((v) => !Number.isFinite(v)))) throw new Error("occluded motion capture is not handled here");
  const cal = handleGravity(manifest);
  const qHS = manifest.rig.handle.ft_sensor.pose.quaternion;
  let sum = 0, count = 0, k = 0;
  for (let i = 0; i < n; i++) {
    const q = grid[i];
    if (q < pose.t[0] || q > pose.t[pose.t.length - 1]) continue;
    while (k < pose.t.length - 2 && pose.t[k + 1] <= q) k++;
    const s = Math.min(1, Math.max(0, (q - pose.t[k]) / (pose.t[k + 1] - pose.t[k])));
    const qWH = slerp(quats[k], quats[k + 1], s);
    const gS = quatRotate(quatConj(qHS), quatRotate(quatConj(qWH), [0, 0, -STANDARD_GRAVITY]));
    const fS = [0, 1, 2].map((a) => raw[a][i] - cal.force_bias_N[a] - cal.connector_mass_kg * gS[a]);
    const fW = quatRotate(qWH, quatRotate(qHS, fS));
    sum += Math.hypot(...fW);
    count++;
  }
  if (count < 2) throw new Error(`trial ${trial.id} has no usable samples`);
  return sum / count;
}

// --- uncertainty (spec chapter 19): Type A only ----------------------------------------------------------
// ln Γ (Lanczos, g = 7, n = 9) and the regularized incomplete beta I_x(a, b) by its continued fraction
// (modified Lentz), for Student's t distribution.
function lnGamma(z) {
  const c = [0.99999999999980993, 676.5203681218851, -1259.1392167224028, 771.32342877765313, -176.61502916214059,
    12.507343278686905, -0.13857109526572012, 9.9843695780195716e-6, 1.5056327351493116e-7];
  if (z < 0.5) return Math.log(Math.PI / Math.abs(Math.sin(Math.PI * z))) - lnGamma(1 - z);
  z -= 1;
  let x = c[0];
  for (let i = 1; i < 9; i++) x += c[i] / (z + i);
  const t = z + 7.5;
  return 0.5 * Math.log(2 * Math.PI) + (z + 0.5) * Math.log(t) - t + Math.log(x);
}

function betaContinuedFraction(x, a, b) {
  const tiny = 1e-300;
  let c = 1, d = 1 - (a + b) * x / (a + 1);
  d = 1 / (Math.abs(d) < tiny ? tiny : d);
  let h = d;
  for (let m = 1; m <= 10000; m++) {
    for (const num of [m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)), -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))]) {
      d = 1 + num * d; d = 1 / (Math.abs(d) < tiny ? tiny : d);
      c = 1 + num / c; if (Math.abs(c) < tiny) c = tiny;
      h *= d * c;
    }
    if (Math.abs(d * c - 1) < 1e-16) break;
  }
  return h;
}

function incompleteBeta(x, a, b) {
  if (x <= 0) return 0;
  if (x >= 1) return 1;
  const front = Math.exp(lnGamma(a + b) - lnGamma(a) - lnGamma(b) + a * Math.log(x) + b * Math.log(1 - x));
  return x < (a + 1) / (a + b + 2) ? front * betaContinuedFraction(x, a, b) / a
    : 1 - front * betaContinuedFraction(1 - x, b, a) / b;
}

// Student's t: P(T ≤ t) for ν degrees of freedom (ν = Infinity: the normal distribution via the same
// function at a large ν would lose digits, so it is refused: every Type A term here has finite ν).
const studentCdf = (t, nu) => {
  const tail = 0.5 * incompleteBeta(nu / (nu + t * t), nu / 2, 0.5);
  return t >= 0 ? 1 - tail : tail;
};

// The quantile t_P(ν) by bisection on the distribution function (to the last bits of a double).
function studentQuantile(p, nu) {
  let lo = 0, hi = 1;
  while (studentCdf(hi, nu) < p) hi *= 2;
  for (let i = 0; i < 200 && hi - lo > 1e-15 * hi; i++) {
    const mid = 0.5 * (lo + hi);
    if (studentCdf(mid, nu) < p) lo = mid; else hi = mid;
  }
  return 0.5 * (lo + hi);
}

// The record of spec §19.4 from the per-repetition values: u_A = s/√n with ν = n − 1 (§19.2), ν_eff by
// Welch–Satterthwaite over the budget (one term here, so ν_eff = n − 1), k = t_{(1+p)/2}(ν_eff), U = k·u.
// Returns null with fewer than two repetitions (§19.2: no record). Only when the session cannot give any
// Type B source of the metric's method (no trial of its rig figure's protocols); otherwise it throws, and
// the case is answered "skipped" — a Type A-only record would understate u.
function typeAUncertainty(values, unit, metric, manifest) {
  const n = values.length;
  if (n < 2) return null;
  const defs = readSchema("uncertainty.json");
  const method = defs.metrics[metric];
  const rig = readSchema("metrics", "rig.json");
  const missing = [];
  for (const src of method.sources) {
    const figure = rig.metrics.find((m) => m.id === defs.sources[src].figure);
    if (manifest.trials.some((t) => figure.protocols.includes(t.protocol))) {
      throw new Error(`the Type B source ${src} (Monte Carlo, spec §19.3) is not implemented in this example`);
    }
    missing.push(src);
  }
  const mean = values.reduce((a, b) => a + b, 0) / n;
  const s = Math.sqrt(values.reduce((a, v) => a + (v - mean) ** 2, 0) / (n - 1));
  const uA = s / Math.sqrt(n);
  const budget = [{ source: "repeatability", type: "A", distribution: "t", u_input: uA, unit, sensitivity: 1.0, contribution: uA, dof: n - 1 }];
  const u = Math.sqrt(budget.reduce((a, b) => a + b.contribution ** 2, 0));
  const nu = u ** 4 / budget.reduce((a, b) => a + b.contribution ** 4 / b.dof, 0);
  const p = defs.parameters.coverage_probability.value;
  const k = studentQuantile((1 + p) / 2, nu);
  return { method: method.method, u, U: k * u, k, coverage_probability: p, dof_eff: nu, budget, mc_draws: null,
    sources_missing: missing.sort() };
}

const VIBRATION = {
  "vibration.rms": ["free_space", "rms"], "vibration.spectral_centroid": ["free_space", "centroid"],
  "vibration.baseline_rms": ["rig.baseline_vibration", "rms"], "vibration.baseline_centroid": ["rig.baseline_vibration", "centroid"],
};

function analyse(session, metric, parameters = {}) {
  const manifest = readManifest(session);
  const record = (id, value, family, def) => ({ id, value, unit: def.unit(id), definition_version: def.version, n: 1 });
  const results = { spec_version: "1.0", implementation: IMPLEMENTATION, session_id: manifest.session_id, metrics: [], unavailable: [] };
  if (metric === "workspace.spec_box_volume") {
    const v = specBoxVolume(manifest);
    const def = definition("workspace");
    if (v === null) results.unavailable.push({ id: metric, code: "E312", reason: "the datasheet has no workspace_box_m" });
    else results.metrics.push(record(metric, v, "workspace", def));
    return results;
  }
  if (metric in VIBRATION) {
    const [protocol, key] = VIBRATION[metric];
    const def = definition("vibration");
    const trials = manifest.trials.filter((t) => t.protocol === protocol);
    if (!trials.length) { results.unavailable.push({ id: metric, code: "E310", reason: `no ${protocol} trial` }); return results; }
    const values = trials.map((t) => trialVibration(session, t, def)[key]);
    results.metrics.push(record(metric, values.reduce((a, b) => a + b, 0) / values.length, "vibration", def));
    return results;
  }
  if (metric === "free_space.force_mean") {
    const def = definition("free_space"), sig = definition("signals");
    const trials = manifest.trials.filter((t) => t.protocol === "free_space");
    if (!trials.length) { results.unavailable.push({ id: metric, code: "E310", reason: "no free_space trial" }); return results; }
    const values = trials.map((t) => trialForceMean(session, manifest, t, sig));
    const rec = { ...record(metric, values.reduce((a, b) => a + b, 0) / values.length, "free_space", def),
      n: values.length, per_repetition: values, trials: trials.map((t) => t.id) };
    if (parameters.uncertainty) rec.uncertainty = typeAUncertainty(values, rec.unit, metric, manifest);
    results.metrics.push(rec);
    return results;
  }
  return null;
}

function main() {
  const rl = readline.createInterface({ input: process.stdin });
  const reply = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
  rl.on("line", (line) => {
    let msg;
    try { msg = JSON.parse(line); } catch (e) { reply({ seq: null, status: "error", message: "malformed request", findings: [] }); return; }
    const seq = msg.seq;
    if (msg.op === "hello") { reply({ seq, status: "ok", protocol: PROTOCOL, implementation: IMPLEMENTATION }); return; }
    if (msg.op === "bye") { reply({ seq, status: "ok" }); rl.close(); return; }
    if (msg.op !== "run") { reply({ seq, status: "error", message: `unknown op ${msg.op}`, findings: [] }); return; }
    try {
      const results = analyse(msg.session, msg.metric, msg.parameters || {});
      if (results === null) reply({ seq, status: "skipped", reason: `${msg.metric} is not implemented in this example` });
      else reply({ seq, status: "ok", results });
    } catch (e) {
      if (e instanceof Rejected) reply({ seq, status: "error", findings: [{ code: e.code, severity: "error", message: e.message }] });
      else reply({ seq, status: "skipped", reason: `cannot handle this session here: ${e.message}` });
    }
  });
}

// A command per case (spec §16.4.1): node haptify.js SESSION OUT [METRIC] writes a results document
// (every supported metric, or just METRIC) or a findings document to OUT.
function commandMode([session, out, metric]) {
  let doc;
  try {
    const wanted = metric ? [metric] : ["workspace.spec_box_volume", ...Object.keys(VIBRATION), "free_space.force_mean"];
    doc = null;
    for (const id of wanted) {
      let r = null;
      try { r = analyse(session, id); } catch (e) { if (e instanceof Rejected) throw e; }
      if (r === null) continue;
      if (doc === null) doc = r; else { doc.metrics.push(...r.metrics); doc.unavailable.push(...r.unavailable); }
    }
    if (doc === null) { process.stderr.write(`nothing this example computes for ${metric || "this session"}\n`); return 3; }
  } catch (e) {
    doc = { findings: [{ code: e.code, severity: "error", message: e.message }] };
  }
  fs.writeFileSync(out, JSON.stringify(doc) + "\n");
  return 0;
}

if (process.argv.length >= 4) process.exitCode = commandMode(process.argv.slice(2));
else main();
