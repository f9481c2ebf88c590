// PersonFollow monitor: a WebSocket client drawing the robot's state on two Canvas2D views.
// No framework and no network beyond this server: the page works beside the robot, offline.
"use strict";

const stats = { frames: 0, lastSeq: 0, latencyMs: [], mode: null, acks: 0, errors: 0, draws: 0, notice: "", refusals: 0,
  session: null, client: null, manualBy: null, scenes: 0, manualSent: 0 };
window.monitorStats = stats;  // read by the browser test and the latency benchmark

const view = document.getElementById("view").getContext("2d");
const plot = document.getElementById("offset").getContext("2d");
const $ = (id) => document.getElementById(id);
let scene = { walls: [] };
let trail = { robot: [], person: [] };
let offsets = [];  // [time_s, offset_px]
let lastTime = -1;
let baseline = true;  // the next state's refusal count is this page's starting point

const token = new URLSearchParams(location.search).get("token");
const wsUrl = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws" +
  (token ? "?token=" + encodeURIComponent(token) : "");
let ws = null;

function connect() {
  ws = new WebSocket(wsUrl);
  ws.onopen = () => { $("conn").textContent = "connected"; $("conn").className = ""; };
  ws.onclose = () => {
    $("conn").textContent = "disconnected (retrying)"; $("conn").className = "bad";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === "state") onState(msg);
    else if (msg.type === "scene") onScene(msg);
    else if (msg.type === "ack") { stats.acks += 1; $("msg").textContent = "ok"; }
    else if (msg.type === "error") { stats.errors += 1; $("msg").textContent = "error: " + msg.error; }
  };
}

function send(obj) { if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj)); }

// The scene comes on every (re)connection and again whenever it changes (each episode's walls).
// A new session (the robot's command started again, the page left open) starts afresh: its
// refusals are counted from zero, so none of them is compared with the last session's count.
function onScene(msg) {
  stats.scenes += 1;
  stats.client = msg.client;
  if (stats.session !== null && msg.session !== stats.session) {
    stats.refusals = 0; stats.notice = ""; baseline = false;
    trail = { robot: [], person: [] }; offsets = []; lastTime = -1;
  }
  stats.session = msg.session;
  scene = msg; scene.walls = scene.walls || [];
  showModes(msg.modes || []);
}

// This page drives in manual only once its user selected manual here: the server names the
// connection whose manual commands it takes (manual_by), and another page's sliders stay idle.
const driving = () => stats.mode === "manual" && stats.manualBy !== null && stats.manualBy === stats.client;
function sendManual() {
  stats.manualSent += 1;
  send({ type: "manual", v_mps: Number($("v").value), w_radps: Number($("w").value) });
}

// The robot says which modes it offers ([[mode, label], ...]: the laws, its agents, manual,
// stop); a button per mode, rebuilt on every (re)connection.
function showModes(modes) {
  const box = $("modes");
  box.replaceChildren();
  for (const [mode, label] of modes) {
    const button = document.createElement("button");
    button.dataset.mode = mode;
    button.textContent = label;
    button.classList.toggle("active", mode === stats.mode);
    button.addEventListener("click", () => send({ type: "mode", mode }));
    box.appendChild(button);
  }
}
for (const id of ["v", "w"]) {
  $(id).addEventListener("input", () => {
    $(id + "val").textContent = Number($(id).value).toFixed(id === "v" ? 2 : 1);
    if (driving()) sendManual();
    else $("msg").textContent = "select manual on this page to drive from it";
  });
}
// While this page drives, its sliders are sent five times a second (the server zeroes a stale one).
setInterval(() => { if (driving()) sendManual(); }, 200);

const fmt = (x, d) => (x === null || x === undefined ? "-" : Number(x).toFixed(d));

function onState(s) {
  stats.frames += 1;
  stats.lastSeq = s.seq;
  stats.mode = s.mode;
  stats.manualBy = s.manual_by === undefined ? null : s.manual_by;
  // The page's wall clock to a fraction of a millisecond, as the server's t_wall: Date.now()
  // counts whole milliseconds, so a state that arrived within the millisecond it was
  // stamped in read as up to 1 ms in the past.
  const latency = performance.timeOrigin + performance.now() - s.t_wall * 1000;
  stats.latencyMs.push(latency);
  if (stats.latencyMs.length > 1000) stats.latencyMs.shift();
  if (s.time_s < lastTime) { trail = { robot: [], person: [] }; offsets = []; }  // a new episode
  lastTime = s.time_s;
  if (s.robot) trail.robot.push(s.robot);
  if (s.person) trail.person.push(s.person);
  if (trail.robot.length > 600) trail.robot.shift();
  if (trail.person.length > 600) trail.person.shift();
  if (s.obs) offsets.push([s.time_s, s.obs[1], s.detected]);
  if (offsets.length > 600) offsets.shift();
  for (const b of document.querySelectorAll("#modes button")) {
    b.classList.toggle("active", b.dataset.mode === s.mode);
  }
  if (baseline) { stats.refusals = s.refusals || 0; baseline = false; }  // before this page: not news
  if (s.refusals > stats.refusals) { stats.refusals = s.refusals; stats.notice = s.notice; $("msg").textContent = "refused: " + s.notice; }
  // a chosen agent is built beside the control loop; the robot runs the old mode meanwhile
  $("mode").textContent = s.mode + (s.loading && s.loading.length ? " (loading " + s.loading.join(", ") + ")" : "");
  $("time").textContent = fmt(s.time_s, 1) + " s" + (s.termination ? " (" + s.termination + ")" : "");
  $("obs").textContent = s.obs ? fmt(s.obs[0], 2) + " m, " + fmt(s.obs[1], 0) + " px" + (s.detected ? "" : " (held)") + (s.obs.length > 2 ? "; ahead " + fmt(s.obs[2], 2) + " m" : "") : "-";
  $("cmd").textContent = s.command && s.command[0] !== null ? fmt(s.command[0], 2) + " m/s, " + fmt(s.command[1], 2) + " rad/s" : "-";
  $("wheels").textContent = s.wheel_target_mps ? s.wheel_target_mps.map((t, i) => fmt(t, 2) + " / " +
    fmt(s.wheel_measured_mps[i], 2)).join(", ") + " m/s" : "-";  // two wheels, or a mecanum base's four
  $("link").textContent = s.link ? s.link.frames_ok + " frames ok, " + s.link.bytes_skipped + " bytes skipped, " +
    s.link.crc_failures + " CRC failures, " + s.link.seq_gaps + " sequence gaps" : "simulation";
  $("latency").textContent = latency.toFixed(1) + " ms";
  draw(s);
}

function draw(s) {
  stats.draws += 1;
  const W = 480, H = 480, scale = 40;  // px per m
  const centre = s.robot || [0, 0, 0];
  const X = (x) => W / 2 + (x - centre[0]) * scale;
  const Y = (y) => H / 2 - (y - centre[1]) * scale;
  view.clearRect(0, 0, W, H);
  view.strokeStyle = "#eee"; view.lineWidth = 1;  // a 1 m grid that moves with the world
  for (let g = Math.floor(centre[0] - 6); g <= centre[0] + 6; g++) { view.beginPath(); view.moveTo(X(g), 0); view.lineTo(X(g), H); view.stroke(); }
  for (let g = Math.floor(centre[1] - 6); g <= centre[1] + 6; g++) { view.beginPath(); view.moveTo(0, Y(g)); view.lineTo(W, Y(g)); view.stroke(); }
  view.strokeStyle = "#333"; view.lineWidth = 3;
  for (const w of scene.walls) { view.beginPath(); view.moveTo(X(w[0]), Y(w[1])); view.lineTo(X(w[2]), Y(w[3])); view.stroke(); }
  for (const [who, colour] of [["person", "#d2691e"], ["robot", "#2a6fdb"]]) {
    const t = trail[who];
    view.strokeStyle = colour; view.lineWidth = 2; view.beginPath();
    t.forEach((p, k) => (k ? view.lineTo(X(p[0]), Y(p[1])) : view.moveTo(X(p[0]), Y(p[1]))));
    view.stroke();
  }
  if (s.person) {
    view.fillStyle = "#d2691e"; view.beginPath(); view.arc(X(s.person[0]), Y(s.person[1]), 0.22 * scale, 0, 2 * Math.PI); view.fill();
  }
  const r = s.robot;
  if (r) {
    view.save(); view.translate(X(r[0]), Y(r[1])); view.rotate(-r[2]);
    view.fillStyle = "#2a6fdb"; view.fillRect(-0.25 * scale, -0.225 * scale, 0.5 * scale, 0.45 * scale);
    view.fillStyle = "#fff"; view.beginPath(); view.moveTo(0.25 * scale, 0); view.lineTo(0.05 * scale, -0.12 * scale); view.lineTo(0.05 * scale, 0.12 * scale); view.fill();
    view.restore();
  } else {
    view.fillStyle = "#666"; view.fillText("no pose (real robot without a world model)", 12, 20);
  }
  // Offset over the last 20 s: the person's image column relative to the centre.
  const PW = 480, PH = 160, span = 20, lim = 320;
  plot.clearRect(0, 0, PW, PH);
  plot.strokeStyle = "#ccc"; plot.beginPath(); plot.moveTo(0, PH / 2); plot.lineTo(PW, PH / 2); plot.stroke();
  plot.fillStyle = "#666"; plot.fillText("offset (px), last 20 s", 6, 12);
  const t1 = s.time_s, t0 = t1 - span;
  plot.strokeStyle = "#2a6fdb"; plot.lineWidth = 1.5; plot.beginPath();
  let started = false;
  for (const [t, o] of offsets) {
    if (t < t0) continue;
    const x = ((t - t0) / span) * PW, y = PH / 2 - (o / lim) * (PH / 2);
    if (started) plot.lineTo(x, y); else { plot.moveTo(x, y); started = true; }
  }
  plot.stroke();
}

connect();
