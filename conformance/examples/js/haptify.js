#!/usr/bin/env node
// A small Haptify implementation in JavaScript (Node.js, no packages): proof that the conformance
// protocol is language-neutral (spec §16.4). It speaks the JSON-lines protocol on stdin/stdout and
// computes, from the session manifest and CSV streams only:
//   workspace.spec_box_volume                (spec §8.6)
//   vibration.rms, vibration.spectral_centroid,
//   vibration.baseline_rms, vibration.baseline_centroid   (spec §10.2–10.6)
// Everything else is answered "skipped". Parameters come from schemas/1.0/metrics/*.json.
"use strict";
const fs = require("fs");
const path = require("path");
const readline = require("readline");

const REPO = path.resolve(__dirname, "..", "..", "..");
const PROTOCOL = 1;
const IMPLEMENTATION = { name: "haptify-js-example", version: "0.1.0" };

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

function sosfilt(sos, x) {
  let y = Float64Array.from(x);
  for (const [b0, b1, b2, , a1, a2] of sos) {
    let z1 = 0, z2 = 0;
    const out = new Float64Array(y.length);
    for (let n = 0; n < y.length; n++) {
      const v = y[n];
      const w = b0 * v + z1;
      z1 = b1 * v - a1 * w + z2;
      z2 = b2 * v - a2 * w;
      out[n] = w;
    }
    y = out;
  }
  return y;
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
  let y = sosfilt(sos, ext).reverse();
  y = sosfilt(sos, y).reverse();
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

const VIBRATION = {
  "vibration.rms": ["free_space", "rms"], "vibration.spectral_centroid": ["free_space", "centroid"],
  "vibration.baseline_rms": ["rig.baseline_vibration", "rms"], "vibration.baseline_centroid": ["rig.baseline_vibration", "centroid"],
};

function analyse(session, metric) {
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
      const results = analyse(msg.session, msg.metric);
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
    const wanted = metric ? [metric] : ["workspace.spec_box_volume", ...Object.keys(VIBRATION)];
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
