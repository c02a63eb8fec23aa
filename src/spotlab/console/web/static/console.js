// spotlab console page: talks to the JSON API and the /api/live WebSocket (docs/console.md).
"use strict";

const token = new URLSearchParams(location.search).get("token");
// What the page received, for the operator's scripts and the browser tests.
// frames3d: 3-D frames drawn (each a new marker frame), for the load benchmark.
const received = { messages: 0, markers: null, markerSeqs: [], status: null, frames3d: 0 };
window.spotlab = received;

function api(path, options = {}) {
  const headers = Object.assign({ "Content-Type": "application/json" }, options.headers || {});
  if (token) headers.Authorization = "Bearer " + token;
  return fetch(path, Object.assign({}, options, { headers })).then(async (r) => {
    const body = await r.json().catch(() => ({}));
    if (!r.ok) throw new Error(body.error || r.status + " " + r.statusText);
    return body;
  });
}

function el(tag, attrs = {}, text = "") {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== "") e.textContent = text;
  return e;
}

// Page writes only where something changed: any write, even of the same text, makes the
// browser restyle, lay out and repaint, and the tables are refreshed 10 times a second.
function setText(e, text) { if (e.textContent !== text) e.textContent = text; }
function setClass(e, cls) { if (e.className !== cls) e.className = cls; }
function setDisabled(e, off) { if (e.disabled !== off) e.disabled = off; }

function fmt(v, digits) {
  if (v === null || v === undefined) return "—";
  return typeof v === "number" && digits !== undefined ? v.toFixed(digits) : String(v);
}

// ---- devices ---------------------------------------------------------------------
function showDevices(devices) {
  const body = document.querySelector("#devices tbody");
  const names = devices.map((d) => d.name).join("\n");
  if (body.dataset.names !== names) {  // rows made again only when the devices change
    body.replaceChildren(...devices.map((d) => el("tr", { "data-device": d.name })));
    body.dataset.names = names;
  }
  devices.forEach((d, row) => {
    const tr = body.rows[row];
    const cells = [
      [d.name, ""], [d.connected ? "connected" : "not connected", d.connected ? "ok" : "bad"],
      [d.family, ""], [d.port, "port"], [fmt(d.rate_hz, 1), ""], [fmt(d.frames), ""],
      [fmt(d.lost_frames), ""], [fmt(d.crc_errors), ""], [fmt(d.resyncs), ""],
      [fmt(d.clock_offset_s, 3), ""], [fmt(d.clock_drift_ppm, 1), ""], [d.last_error || "", ""],
    ];
    cells.forEach(([text, cls], k) => {
      const td = tr.cells[k] || tr.appendChild(document.createElement("td"));
      setText(td, text);
      setClass(td, cls);
      if (cls === "port" && td.title !== text) td.title = text;
    });
  });
}

// The device form (outside the table, whose cells are refreshed with every slow message).
function showDeviceChoices(devices) {
  const select = document.getElementById("device-name");
  const names = devices.map((d) => d.name);
  if (Array.from(select.options).map((o) => o.value).join("\n") !== names.join("\n")) {
    const chosen = select.value;
    select.replaceChildren(...names.map((n) => el("option", { value: n }, n)));
    if (names.includes(chosen)) select.value = chosen;
  }
  const d = devices.find((x) => x.name === select.value);
  setDisabled(document.getElementById("device-set-rate"), recording || !(d && d.rate_settable));
  // the chosen device's family settings, each titled with what it is and what it is given
  const setting = document.getElementById("device-setting");
  const keys = d ? Object.keys(d.settings || {}) : [];
  const shown = keys.map((k) => k + "=" + ((d.set || {})[k] ?? "")).join("\n");
  if (setting.dataset.shown !== (d ? d.name : "") + "\n" + shown) {
    const chosen = setting.value;
    setting.replaceChildren(...keys.map((k) => {
      const given = (d.set || {})[k];
      return el("option", { value: k, title: d.settings[k] + (given === undefined ? "" : "; given " + given) }, k);
    }));
    if (keys.includes(chosen)) setting.value = chosen;
    setting.dataset.shown = (d ? d.name : "") + "\n" + shown;
  }
  setDisabled(document.getElementById("device-set"), recording || keys.length === 0);
  // a device reconnects alone in the running session, a trial being recorded goes on
  setDisabled(document.getElementById("device-reconnect"), false);
}

function deviceAction(what, body) {
  const name = document.getElementById("device-name").value;
  say("device-msg", name + ": " + what + "…");
  api("/api/devices/" + encodeURIComponent(name) + "/" + what, { method: "POST", body: JSON.stringify(body) })
    .then((r) => say("device-msg", name + ": " + what + " asked; " + (r.reconnecting === "device"
      ? "it reconnects alone, the others go on" : "the devices start again")))
    .catch((e) => say("device-msg", name + ": " + e.message, true));
}
document.getElementById("device-reconnect").addEventListener("click", () => deviceAction("reconnect", {}));
document.getElementById("device-set-rate").addEventListener("click", () =>
  deviceAction("configure", { rate_hz: Number(document.getElementById("device-rate").value) }));
document.getElementById("device-set").addEventListener("click", () => {
  const key = document.getElementById("device-setting").value;
  const text = document.getElementById("device-value").value.trim();
  // a number where it reads as one ("200", "1e3"), a word otherwise ("off", "auto")
  const value = text !== "" && !Number.isNaN(Number(text)) ? Number(text) : text;
  deviceAction("configure", { settings: { [key]: value } });
});

function showBanner(status, devices) {
  const lines = [];
  for (const d of devices) if (d.last_error) lines.push(d.name + ": " + d.last_error);
  if (status && status.errors && status.errors.lab) lines.push(status.errors.lab);
  const banner = document.getElementById("banner");
  if (banner.hidden !== (lines.length === 0)) banner.hidden = lines.length === 0;
  setText(banner, lines.join(" · "));
}

// ---- 2-D views -------------------------------------------------------------------
const extents = {};
function camCanvas(stream, i) {
  const id = "cam-" + stream + "-" + i;
  let c = document.getElementById(id);
  if (!c) {
    const box = el("div", { class: "cam" });
    c = el("canvas", { id, width: 200, height: 200, "data-stream": stream });
    box.appendChild(c);
    box.appendChild(el("div", {}, stream + " camera " + (i + 1)));
    document.getElementById("views2d").appendChild(box);
  }
  return c;
}

function show2d(views) {
  for (const [stream, v] of Object.entries(views)) {
    let ext = extents[stream];
    if (!ext) ext = extents[stream] = v.units === "count" ? [4095, 4095] : [640, 480];
    v.cameras.forEach((spots, i) => {
      for (const [x, y] of spots) {
        if (v.units !== "count") { ext[0] = Math.max(ext[0], x); ext[1] = Math.max(ext[1], y); }
      }
      const c = camCanvas(stream, i);
      const g = c.getContext("2d");
      g.fillStyle = "#10161d";
      g.fillRect(0, 0, c.width, c.height);
      g.fillStyle = "#ffd54f";
      for (const [x, y] of spots) {
        g.beginPath();
        g.arc((x / (1.05 * ext[0])) * c.width, (y / (1.05 * ext[1])) * c.height, 3, 0, 2 * Math.PI);
        g.fill();
      }
    });
  }
}

// ---- 3-D view ------------------------------------------------------------------------
const view = { az: -0.9, el: 0.45, dist: 9000, half: 2500, drawnSeq: null };
function project(p, c) {
  const [x, y, z] = p;
  const ca = Math.cos(view.az), sa = Math.sin(view.az);
  const xr = ca * x - sa * y, yr = sa * x + ca * y;
  const ce = Math.cos(view.el), se = Math.sin(view.el);
  const depth = view.dist + yr * ce + (z - 800) * se;  // towards the scene
  const up = (z - 800) * ce - yr * se;
  const f = (c.height * 1.1 * view.dist) / (2 * view.half) / depth;
  return [c.width / 2 + xr * f, c.height / 2 - up * f];
}

// The floor, the axes and the cameras change only with the view or the rig: drawn once
// into an offscreen canvas and copied under each new frame of markers.
const backdrop = { canvas: null, key: "" };
function drawBackdrop(c, cameras) {
  const key = [c.width, c.height, view.az, view.el, view.dist, view.half,
    JSON.stringify(cameras || [])].join("|");
  if (backdrop.key === key) return backdrop.canvas;
  const b = backdrop.canvas || document.createElement("canvas");
  b.width = c.width; b.height = c.height;
  const g = b.getContext("2d");
  g.fillStyle = "#10161d";
  g.fillRect(0, 0, b.width, b.height);
  g.strokeStyle = "#35506b";
  g.lineWidth = 1;
  g.beginPath();
  for (let k = -view.half; k <= view.half; k += 500) {  // the floor, z = 0, every 0.5 m
    for (const [a, e] of [[[k, -view.half, 0], [k, view.half, 0]], [[-view.half, k, 0], [view.half, k, 0]]]) {
      const [x0, y0] = project(a, b), [x1, y1] = project(e, b);
      g.moveTo(x0, y0); g.lineTo(x1, y1);
    }
  }
  g.stroke();
  for (const [axis, colour] of [[[500, 0, 0], "#e57373"], [[0, 500, 0], "#81c784"], [[0, 0, 500], "#64b5f6"]]) {
    const [x0, y0] = project([0, 0, 0], b), [x1, y1] = project(axis, b);
    g.strokeStyle = colour; g.beginPath(); g.moveTo(x0, y0); g.lineTo(x1, y1); g.stroke();
  }
  g.font = "10px sans-serif";
  for (const cam of cameras || []) {  // the rig's cameras: centre and optical axis
    const [x, y] = project(cam.center, b);
    const tip = cam.center.map((v, k) => v + 400 * cam.axis[k]);
    const [tx, ty] = project(tip, b);
    g.strokeStyle = "#ffb74d"; g.beginPath(); g.moveTo(x, y); g.lineTo(tx, ty); g.stroke();
    g.fillStyle = "#ffb74d"; g.fillRect(x - 4, y - 4, 8, 8);
    g.fillText(cam.name, x + 6, y + 10);
  }
  backdrop.canvas = b;
  backdrop.key = key;
  return b;
}

function show3d(markers, cameras) {
  for (const cam of cameras || []) {  // the floor and view reach the cameras
    const reach = Math.max(Math.abs(cam.center[0]), Math.abs(cam.center[1])) + 500;
    if (reach > view.half) view.half = Math.ceil(reach / 500) * 500;
  }
  const c = document.getElementById("view3d");
  // opaque (the backdrop fills it) and CPU-backed: neither changed Chromium's measured
  // share here, but the console's latency was measured with them (docs/console.md)
  const g = c.getContext("2d", { alpha: false, willReadFrequently: true });
  g.drawImage(drawBackdrop(c, cameras), 0, 0);
  if (!markers) return;
  if (markers.seq !== view.drawnSeq) { view.drawnSeq = markers.seq; received.frames3d += 1; }
  // one path for the stems to the floor, one for the dots, then the labels
  const shown = [];
  markers.points.forEach((p, i) => { if (p) shown.push([project(p, c), project([p[0], p[1], 0], c), i]); });
  g.strokeStyle = "#ffffff22"; g.lineWidth = 1;
  g.beginPath();
  for (const [[x, y], [fx, fy]] of shown) { g.moveTo(fx, fy); g.lineTo(x, y); }
  g.stroke();
  g.fillStyle = "#4dd0e1";
  g.beginPath();
  for (const [[x, y]] of shown) { g.moveTo(x + 4, y); g.arc(x, y, 4, 0, 2 * Math.PI); }
  g.fill();
  for (const [[x, y], , i] of shown) {
    const sprite = labelSprite(markers.labels[i] || "");
    if (sprite) g.drawImage(sprite, x + 6, y - 4 - LABEL_ASCENT);
  }
}

// Each label's text drawn once into a small canvas and copied from there in every frame:
// a software renderer lays out and rasterises text far more slowly than it copies pixels.
const LABEL_ASCENT = 9;
const labelSprites = new Map();
function labelSprite(text) {
  if (!text) return null;
  let sprite = labelSprites.get(text);
  if (sprite) return sprite;
  if (labelSprites.size > 2000) labelSprites.clear();  // many labels over a long session
  sprite = document.createElement("canvas");
  const g = sprite.getContext("2d");
  g.font = "10px sans-serif";
  sprite.width = Math.ceil(g.measureText(text).width) + 2;
  sprite.height = 13;
  g.font = "10px sans-serif";  // resizing a canvas resets its state
  g.fillStyle = "#cfd8dc";
  g.fillText(text, 0, LABEL_ASCENT);
  labelSprites.set(text, sprite);
  return sprite;
}

// ---- recording and trials ------------------------------------------------------------
let recording = false;
function showMode(status) {
  recording = status.mode === "recording";
  setText(document.getElementById("mode"), recording ? "● recording " + status.trial.id : "preview");
  setClass(document.getElementById("mode"), recording ? "bad" : "");
  setDisabled(document.getElementById("record"), recording);
  setDisabled(document.getElementById("stop"), !recording);
  setText(document.getElementById("lab"), (status.simulated ? "simulated lab · " : "") + status.lab);
  setText(document.getElementById("live3d"), status.live_3d === "on" ? "" : "(" + status.live_3d + ")");
}

function say(id, text, bad) {
  const p = document.getElementById(id);
  p.textContent = text;
  p.className = "msg " + (bad ? "bad" : "");
}

document.getElementById("record-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const f = new FormData(ev.target);
  const body = { subject: f.get("subject"), session: f.get("session"), trial: f.get("trial"), notes: f.get("notes") };
  if (f.get("seconds")) body.seconds = Number(f.get("seconds"));
  api("/api/trials/start", { method: "POST", body: JSON.stringify(body) })
    .then((t) => { say("record-msg", "recording " + t.id + " → " + t.journal); refreshTrials(); })
    .catch((e) => say("record-msg", e.message, true));
});

document.getElementById("stop").addEventListener("click", () => {
  api("/api/trials/stop", { method: "POST", body: "{}" })
    .then((t) => { say("record-msg", t.id + ": " + t.state + ", " + t.duration_s + " s"); refreshTrials(); })
    .catch((e) => say("record-msg", e.message, true));
});

function sum(obj) { return Object.values(obj || {}).reduce((a, b) => a + b, 0); }

function exportTrial(id, button) {
  button.disabled = true;
  say("trials-msg", "exporting " + id + "…");
  api("/api/trials/" + encodeURIComponent(id) + "/export", { method: "POST", body: JSON.stringify({ format: "c3d" }) })
    .then((r) => { say("trials-msg", id + " → " + r.file + " (" + r.frames + " frames, " + r.markers + " markers)"); refreshTrials(); })
    .catch((e) => say("trials-msg", id + ": " + e.message, true))
    .finally(() => { button.disabled = false; });
}

function refreshTrials() {
  return api("/api/trials").then(({ trials }) => {
    const body = document.querySelector("#trials tbody");
    body.replaceChildren();
    for (const t of trials.slice().reverse()) {
      const tr = el("tr", { "data-trial": t.id });
      const lost = Object.entries(t.lost).map(([k, v]) => k + " " + v).join(", ");
      for (const text of [t.id, t.started_at.replace("T", " ").slice(0, 19), fmt(t.duration_s, 2),
                          String(sum(t.frames)), lost, t.state + (t.exports.length ? " · " + t.exports.join(", ") : ""),
                          [t.notes, ...t.messages].filter(Boolean).join(" · "), processedText(t.processing)]) {
        tr.appendChild(el("td", {}, text));
      }
      const td = el("td");
      const b = el("button", { class: "export", type: "button" }, "Export C3D");
      b.disabled = t.state === "recording" || t.state === "failed";
      b.addEventListener("click", () => exportTrial(t.id, b));
      td.appendChild(b);
      const pb = el("button", { class: "process", type: "button" }, "Process");
      pb.disabled = b.disabled;
      pb.addEventListener("click", () => processTrial(t.id));
      td.appendChild(pb);
      tr.appendChild(td);
      body.appendChild(tr);
    }
  }).catch((e) => say("trials-msg", e.message, true));
}

// ---- processing: "Process" reconstructs a recorded trial in the console's worker thread,
// follows its progress, shows the quality numbers and exports the result ------------
const QUALITY = [
  ["frames", "frames", 0], ["markers", "markers", 0], ["cameras", "cameras", 0],
  ["rate_hz", "rate (Hz)", 1], ["reconstructed_fraction", "reconstructed", "%"],
  ["labelled_fraction", "labelled", "%"], ["markers_reconstructed", "markers seen", 0],
  ["rms_ray_px", "RMS ray residual (px)", 3], ["gaps", "gaps", 0],
  ["longest_gap_frames", "longest gap (frames)", 0], ["markers_never_seen", "markers never seen", 0],
  ["lost_frames", "lost frames", 0], ["ghosts_rejected", "ghosts rejected", 0],
];

function qualityValue(v, how) {
  if (v === null || v === undefined) return "—";
  return how === "%" ? (100 * v).toFixed(2) + " %" : fmt(v, typeof v === "number" && !Number.isInteger(v) ? how : undefined);
}

// The trials table's "processed" cell: the last processing's headline numbers.
function processedText(p) {
  if (!p || !p.quality) return "";
  const q = p.quality;
  const share = q.reconstructed_fraction ?? q.labelled_fraction;
  return qualityValue(share, "%") + " · RMS " + qualityValue(q.rms_ray_px, 2) + " · " + q.gaps + " gaps";
}

let processing = null; // id of the trial shown in the panel
let processTimer = null;

function showJob(job) {
  document.getElementById("process-trial").textContent = job.trial + " (" + (job.path || "…") + ")";
  const bar = document.getElementById("process-progress");
  bar.value = job.state === "done" ? 1 : job.fraction;
  const stage = job.state === "running"
    ? (job.stage || "starting") + " " + (job.detail || "") : job.state + " in " + fmt(job.elapsed_s, 1) + " s";
  say("process-stage", stage, job.state === "failed");
  const body = document.querySelector("#process-quality tbody");
  body.replaceChildren();
  const q = job.quality || {};
  for (const [key, label, how] of QUALITY) {
    if (!(key in q)) continue;
    const tr = el("tr", { "data-key": key });
    tr.appendChild(el("th", {}, label));
    tr.appendChild(el("td", {}, qualityValue(q[key], how)));
    body.appendChild(tr);
  }
  for (const [cam, rms] of Object.entries(q.rms_ray_px_per_camera || {})) {
    const tr = el("tr", { "data-key": "rms:" + cam });
    tr.appendChild(el("th", {}, "RMS ray residual (px) " + cam));
    tr.appendChild(el("td", {}, fmt(rms, 3)));
    body.appendChild(tr);
  }
  const notes = document.getElementById("process-notes");
  notes.replaceChildren(...[job.error, ...job.notes].filter(Boolean).map((n) => el("li", {}, n)));
  document.getElementById("process-actions").hidden = job.state !== "done";
}

function pollJob(id) {
  clearTimeout(processTimer);
  api("/api/trials/" + encodeURIComponent(id) + "/process").then((job) => {
    if (processing !== id) return;
    showJob(job);
    if (job.state === "running") processTimer = setTimeout(() => pollJob(id), 250);
    else refreshTrials();
  }).catch((e) => say("process-msg", e.message, true));
}

function processTrial(id) {
  processing = id;
  document.getElementById("process-panel").hidden = false;
  say("process-msg", "");
  api("/api/trials/" + encodeURIComponent(id) + "/process", { method: "POST", body: "{}" })
    .then((job) => { showJob(job); pollJob(id); })
    .catch((e) => say("process-msg", id + ": " + e.message, true));
}

for (const format of ["c3d", "trc"]) {
  const button = document.getElementById("process-" + format);
  button.addEventListener("click", () => {
    button.disabled = true;
    api("/api/trials/" + encodeURIComponent(processing) + "/export", { method: "POST", body: JSON.stringify({ format }) })
      .then((r) => { say("process-msg", processing + " → " + r.file + " (" + r.frames + " frames, " + r.markers + " markers)"); refreshTrials(); })
      .catch((e) => say("process-msg", e.message, true))
      .finally(() => { button.disabled = false; });
  });
}

// ---- a marker over time (client side, from the live messages) ----------------------
const SERIES_S = 5;
const series = []; // [time_s, points] of the last SERIES_S seconds
received.series = series;

function keepSeries(markers) {
  if (!markers || markers.time_s === null || markers.time_s === undefined) return;
  const last = series[series.length - 1];
  if (last && markers.time_s < last[0]) series.length = 0; // a new session: time restarts
  if (last && markers.time_s === last[0]) return;
  series.push([markers.time_s, markers.points]);
  while (series.length && series[0][0] < markers.time_s - SERIES_S) series.shift();
  const select = document.getElementById("series-marker");
  const labels = markers.labels || [];
  if (select.options.length !== labels.length) {
    const chosen = select.value;
    select.replaceChildren(...labels.map((l, i) => el("option", { value: String(i) }, l || "m" + i)));
    if (chosen && Number(chosen) < labels.length) select.value = chosen;
  }
}

function showSeries() {
  const canvas = document.getElementById("series");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  const m = Number(document.getElementById("series-marker").value || 0);
  if (series.length < 2) return;
  const t1 = series[series.length - 1][0];
  const colours = ["#ef5350", "#66bb6a", "#42a5f5"];
  for (let axis = 0; axis < 3; axis++) {
    const values = series.map(([t, pts]) => [t, pts[m] ? pts[m][axis] : null]);
    const seen = values.filter(([, v]) => v !== null).map(([, v]) => v);
    if (!seen.length) continue;
    const lo = Math.min(...seen), hi = Math.max(...seen), span = Math.max(hi - lo, 1);
    const band = canvas.height / 3;
    g.strokeStyle = colours[axis];
    g.beginPath();
    let pen = false;
    for (const [t, v] of values) {
      if (v === null) { pen = false; continue; }
      const x = canvas.width * (1 - (t1 - t) / SERIES_S);
      const y = band * axis + band - 4 - (band - 8) * (v - lo) / span;
      if (pen) g.lineTo(x, y); else g.moveTo(x, y);
      pen = true;
    }
    g.stroke();
    g.fillStyle = colours[axis];
    g.fillText(fmt(seen[seen.length - 1], 1) + " mm", 4, band * axis + 12);
  }
}

// ---- link health over time (GET /api/health once a second) ----------------------------
function drawHealth(canvas, d) {
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  const n = 60, w = canvas.width / n, h = canvas.height;
  const fps = Math.max(1, ...d.frames);
  const offset = n - d.t.length;
  g.strokeStyle = "#90a4ae";
  g.beginPath();
  d.frames.forEach((f, i) => { const x = (offset + i + 0.5) * w, y = h - 2 - (h - 4) * f / fps; if (i) g.lineTo(x, y); else g.moveTo(x, y); });
  g.stroke();
  const worst = Math.max(1, ...d.lost, ...d.crc);
  d.t.forEach((_, i) => {
    const x = (offset + i) * w;
    if (d.lost[i] > 0) { g.fillStyle = "#ef5350"; const bh = Math.max(2, (h / 2) * d.lost[i] / worst); g.fillRect(x, h - bh, w / 2, bh); }
    if (d.crc[i] > 0) { g.fillStyle = "#ffa726"; const bh = Math.max(2, (h / 2) * d.crc[i] / worst); g.fillRect(x + w / 2, h - bh, w / 2, bh); }
  });
}

function refreshHealth() {
  api("/api/health").then((health) => {
    received.health = health;
    const box = document.getElementById("health");
    for (const [name, d] of Object.entries(health.devices)) {
      let canvas = box.querySelector("canvas[data-device='" + CSS.escape(name) + "']");
      let label = box.querySelector("div[data-device='" + CSS.escape(name) + "'] span");
      if (!canvas) {
        const div = el("div", { class: "dev", "data-device": name });
        label = el("span");
        canvas = el("canvas", { width: "480", height: "40", "data-device": name });
        div.append(label, canvas);
        box.appendChild(div);
      }
      const sumOf = (a) => a.reduce((x, y) => x + y, 0);
      label.textContent = name + ": " + sumOf(d.lost) + " lost, " + sumOf(d.crc) + " CRC errors in " + d.t.length + " s · "
        + fmt(d.t.length > 1 ? d.frames[d.t.length - 1] / (d.t[d.t.length - 1] - d.t[d.t.length - 2]) : null, 0) + " frames/s";
      drawHealth(canvas, d);
    }
  }).catch(() => {});
}

// ---- calibration wizard (GET /api/calibration, POST .../wand, lframe, run, accept) ----
let calTimer = null;
const CAL_WORDS = {
  idle: "not started", wand: "recording the wand dance: wave it through the volume",
  wand_done: "wand dance recorded", lframe: "recording the L-frame: leave it still on the floor",
  lframe_done: "L-frame recorded", calibrating: "calibrating…", calibrated: "calibrated: check the report, then accept",
  accepted: "accepted", failed: "failed",
};

function showCalibration(c) {
  received.calibration = c;
  const busy = ["wand", "lframe", "calibrating"].includes(c.step);
  let text = CAL_WORDS[c.step] || c.step;
  if (c.step === "accepted") text += ": " + c.rig + " is the rig of session " + c.subject + "/" + c.session;
  if (c.error) text += ": " + c.error;
  say("cal-step", text, c.step === "failed");
  document.getElementById("cal-wand").disabled = busy;
  const select = document.getElementById("cal-device");  // a lab file's camera systems
  const choices = c.devices || [];
  if (Array.from(select.options).map((o) => o.value).join("\n") !== choices.join("\n")) {
    select.replaceChildren(...choices.map((n) => el("option", { value: n }, n)));
  }
  if (c.device && choices.includes(c.device)) select.value = c.device;
  document.getElementById("cal-device-label").hidden = choices.length === 0;
  document.getElementById("cal-lframe").disabled = busy || !["wand_done", "lframe_done", "failed"].includes(c.step) || !c.wand_trial;
  document.getElementById("cal-run").disabled = busy || !c.lframe_trial || c.step === "accepted";
  document.getElementById("cal-accept").disabled = c.step !== "calibrated";
  const report = c.report || { cameras: [] };
  const names = Array.from(new Set([...Object.keys(c.coverage || {}), ...report.cameras.map((x) => x.name)]));
  const body = document.querySelector("#cal-coverage tbody");
  body.replaceChildren();
  for (const name of names) {
    const tr = el("tr", { "data-camera": name });
    const share = (c.coverage || {})[name];
    const td = el("td");
    if (share !== undefined) {
      const bar = el("span", { class: "bar" });
      bar.style.width = (100 * share).toFixed(0) + "px";
      td.append(bar, document.createTextNode((100 * share).toFixed(1) + " %"));
    }
    const cam = report.cameras.find((x) => x.name === name);
    tr.append(el("td", {}, name), td,
      el("td", {}, cam ? fmt(cam.reprojection_rms, 3) + " " + report.units : ""),
      el("td", {}, cam ? String(cam.observations) : ""));
    body.appendChild(tr);
  }
  say("cal-verdict", c.report ? "verdict: " + c.report.verdict + ", wand length SD " + fmt(c.report.wand_sd_mm, 3) + " mm"
    + (c.report.reasons.length ? " · " + c.report.reasons.join(" · ") : "") : "");
  const img = document.getElementById("cal-figure");
  const shown = c.step === "calibrated" || c.step === "accepted";
  if (shown && img.dataset.candidate !== c.candidate) {
    img.dataset.candidate = c.candidate;
    img.src = "/api/calibration/figure?t=" + Date.now() + (token ? "&token=" + encodeURIComponent(token) : "");
  }
  img.hidden = !shown;
  clearTimeout(calTimer);
  if (busy) calTimer = setTimeout(pollCalibration, 300);
}

function pollCalibration() {
  api("/api/calibration").then(showCalibration).catch((e) => say("cal-step", e.message, true));
}

function calibrationStep(step, body) {
  api("/api/calibration/" + step, { method: "POST", body: JSON.stringify(body || {}) })
    .then((c) => { showCalibration(c); refreshTrials(); })
    .catch((e) => say("cal-step", e.message, true));
}
document.getElementById("cal-wand").addEventListener("click", () => calibrationStep("wand", {
  device: document.getElementById("cal-device").value || null,
  subject: document.getElementById("cal-subject").value, session: document.getElementById("cal-session").value,
  seconds: Number(document.getElementById("cal-wand-seconds").value),
}));
document.getElementById("cal-lframe").addEventListener("click", () => calibrationStep("lframe", {
  seconds: Number(document.getElementById("cal-lframe-seconds").value),
}));
document.getElementById("cal-run").addEventListener("click", () => calibrationStep("run"));
document.getElementById("cal-accept").addEventListener("click", () => calibrationStep("accept"));

// ---- the live socket ------------------------------------------------------------------
let lastMode = null;
function connect() {
  const proto = location.protocol === "https:" ? "wss://" : "ws://";
  const ws = new WebSocket(proto + location.host + "/api/live" + (token ? "?token=" + encodeURIComponent(token) : ""));
  const link = document.getElementById("link");
  ws.onopen = () => { link.textContent = "live"; link.className = "ok"; };
  ws.onclose = () => { link.textContent = "disconnected: retrying"; link.className = "bad"; setTimeout(connect, 1000); };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    received.messages += 1;
    if (m.slow !== undefined) { received.status = m.status; received.devices = m.devices; }
    if (m.markers) {
      received.markers = m.markers;
      received.markerSeqs.push(m.markers.seq);
      if (received.markerSeqs.length > 100) received.markerSeqs.shift();
    }
    if (m.slow !== undefined) {  // the tables and 2-D views: about 10 times a second
      showMode(m.status);
      showDevices(m.devices);
      showDeviceChoices(m.devices);
      showBanner(m.status, m.devices);
      show2d(m.views);
    }
    if (!received.status) return;
    show3d(m.markers, received.status.cameras);
    keepSeries(m.markers);
    if (m.slow !== undefined) showSeries();  // 5 s of history: 10 redraws a second show it
    if (lastMode !== received.status.mode) { lastMode = received.status.mode; refreshTrials(); }
  };
}

refreshTrials();
connect();
setInterval(refreshTrials, 3000);
refreshHealth();
setInterval(refreshHealth, 1000);
pollCalibration();
