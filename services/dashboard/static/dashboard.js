// proactive-nav dashboard: draws what the websocket pushes (docs/DASHBOARD.md), and writes
// people's rows (goal, user_command, strategy, zone) through the HTTP endpoints. Plain JS,
// no build.
"use strict";

const PALETTE = ["#d6336c", "#1c7ed6", "#2f9e44", "#f08c00", "#7048e8", "#0c8599", "#e8590c"];
const MARGIN = 16;

const state = {
  world: { map: null, chargers: [], zones: [] },
  drawing: null, // the vertices of a zone being drawn ([[x, y], ...]), or null
  robots: {},
  strategies: [],
  timeline: [],
  selected: null,
  connected: false,
  drawn: {}, // robot -> {x, y, px, py}: where the robot was last drawn (world and canvas)
  gridImage: null,
  frames: 0,
  route: [], // waypoints placed with Shift (x, y, yaw?), sent with the next goal
  press: null, // where a press on the map began (canvas px), while the button is down
  dragTo: null, // where the pointer is while dragging a heading
  dragged: false, // the last press was a drag: the click that follows it is not a goal
};
window.pnavDashboard = state; // for people poking at the console, and for the browser test

const $ = (id) => document.getElementById(id);
const canvas = $("map");
const ctx = canvas.getContext("2d");

function colorOf(robot) {
  const ids = Object.keys(state.robots).sort();
  return PALETTE[Math.max(0, ids.indexOf(robot)) % PALETTE.length];
}

function fmt(v, digits = 2) {
  return v === null || v === undefined ? "-" : Number(v).toFixed(digits);
}

function el(tag, attrs = {}, text = "") {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text) node.textContent = text;
  return node;
}

// -- geometry: world metres <-> canvas pixels (y up in the world, down on the canvas) ------
function bounds() {
  const m = state.world.map;
  if (m) {
    return { x0: m.origin[0], y0: m.origin[1], x1: m.origin[0] + m.width * m.resolution,
             y1: m.origin[1] + m.height * m.resolution };
  }
  return { x0: -1, y0: -1, x1: 11, y1: 9 };
}

function transform() {
  const b = bounds();
  const s = Math.min((canvas.width - 2 * MARGIN) / (b.x1 - b.x0),
                     (canvas.height - 2 * MARGIN) / (b.y1 - b.y0));
  return { b, s };
}

function toCanvas(x, y) {
  const { b, s } = transform();
  return [MARGIN + (x - b.x0) * s, canvas.height - MARGIN - (y - b.y0) * s];
}

function toWorld(px, py) {
  const { b, s } = transform();
  return [b.x0 + (px - MARGIN) / s, b.y0 + (canvas.height - MARGIN - py) / s];
}
state.toCanvas = toCanvas;
state.toWorld = toWorld;

// -- drawing -------------------------------------------------------------------------------
function buildGrid() {
  const m = state.world.map;
  state.gridImage = null;
  if (!m) return;
  const cells = Uint8Array.from(atob(m.grid), (c) => c.charCodeAt(0));
  const off = document.createElement("canvas");
  off.width = m.width;
  off.height = m.height;
  const img = off.getContext("2d").createImageData(m.width, m.height);
  for (let j = 0; j < m.height; j++) {
    for (let i = 0; i < m.width; i++) {
      const v = cells[j * m.width + i];
      const shade = v === 255 ? 205 : Math.round(250 - (v / 100) * 210);
      const k = ((m.height - 1 - j) * m.width + i) * 4; // row 0 is the bottom row
      img.data[k] = img.data[k + 1] = img.data[k + 2] = shade;
      img.data[k + 3] = 255;
    }
  }
  off.getContext("2d").putImageData(img, 0, 0);
  state.gridImage = off;
}

function circle(x, y, r, fill, stroke) {
  const [px, py] = toCanvas(x, y);
  const { s } = transform();
  ctx.beginPath();
  ctx.arc(px, py, Math.max(2, r * s), 0, 2 * Math.PI);
  if (fill) { ctx.fillStyle = fill; ctx.fill(); }
  if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = 2; ctx.stroke(); }
}

// a heading: an arrow 28 px long from (x, y) along yaw (rad, map frame)
function arrow(x, y, yaw, color) {
  const [px, py] = toCanvas(x, y);
  const ex = px + 28 * Math.cos(yaw), ey = py - 28 * Math.sin(yaw);
  ctx.strokeStyle = color;
  ctx.lineWidth = 3;
  ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(ex, ey);
  for (const side of [-1, 1]) {
    const a = -yaw + Math.PI + side * 0.5;
    ctx.moveTo(ex, ey); ctx.lineTo(ex + 9 * Math.cos(a), ey + 9 * Math.sin(a));
  }
  ctx.stroke();
  ctx.lineWidth = 2;
}

// a route: its waypoints in order, numbered, filled once reached (red when failed)
function drawRoute(route, goal, color) {
  if (!route.length) return;
  ctx.strokeStyle = color;
  ctx.setLineDash([2, 4]);
  ctx.beginPath();
  route.forEach((w, i) => {
    const [px, py] = toCanvas(w.x, w.y);
    if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
  });
  const [gx, gy] = toCanvas(goal.x, goal.y);
  ctx.lineTo(gx, gy);
  ctx.stroke();
  ctx.setLineDash([]);
  for (const w of route) {
    const fill = w.status === "reached" ? color : w.status === "failed" ? "#e03131" : "#fff";
    circle(w.x, w.y, 0.06, fill, w.stop || w.yaw !== null ? "#111" : color);
    if (w.yaw !== null && w.yaw !== undefined) arrow(w.x, w.y, w.yaw, color);
    const [px, py] = toCanvas(w.x, w.y);
    ctx.fillStyle = "#111";
    ctx.font = "11px system-ui";
    ctx.fillText(String(w.seq), px + 6, py - 6);
  }
}

function drawPlacing() {
  // the waypoints placed so far, and the heading being dragged
  state.route.forEach((w, i) => {
    circle(w.x, w.y, 0.06, "#fff", "#555");
    if (w.yaw !== undefined) arrow(w.x, w.y, w.yaw, "#555");
    const [px, py] = toCanvas(w.x, w.y);
    ctx.fillStyle = "#555";
    ctx.fillText(String(i + 1), px + 6, py - 6);
  });
  if (state.press && state.dragTo) {
    ctx.strokeStyle = "#555";
    ctx.setLineDash([4, 3]);
    ctx.beginPath();
    ctx.moveTo(state.press[0], state.press[1]); ctx.lineTo(state.dragTo[0], state.dragTo[1]);
    ctx.stroke();
    ctx.setLineDash([]);
  }
}

function drawRobot(id, r) {
  const color = colorOf(id);
  if (r.path && r.path.xs.length > 1) {
    ctx.beginPath();
    r.path.xs.forEach((x, i) => {
      const [px, py] = toCanvas(x, r.path.ys[i]);
      if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    });
    ctx.strokeStyle = color;
    ctx.setLineDash([6, 4]);
    ctx.lineWidth = 2;
    ctx.stroke();
    ctx.setLineDash([]);
  }
  if (r.goal && r.goal.status === "active") {
    drawRoute(r.route || [], r.goal, color);
    circle(r.goal.x, r.goal.y, r.goal.tolerance_m, null, color);
    const [gx, gy] = toCanvas(r.goal.x, r.goal.y);
    ctx.strokeStyle = color;
    ctx.beginPath();
    ctx.moveTo(gx - 7, gy - 7); ctx.lineTo(gx + 7, gy + 7);
    ctx.moveTo(gx + 7, gy - 7); ctx.lineTo(gx - 7, gy + 7);
    ctx.stroke();
    if (r.goal.yaw !== null && r.goal.yaw !== undefined) arrow(r.goal.x, r.goal.y, r.goal.yaw, color);
  }
  if (r.scan) {
    ctx.fillStyle = "rgba(230, 30, 30, 0.75)";
    const p = r.scan.points;
    for (let i = 0; i + 1 < p.length; i += 2) {
      const [px, py] = toCanvas(p[i], p[i + 1]);
      ctx.fillRect(px - 1.5, py - 1.5, 3, 3);
    }
  }
  if (!r.pose) return;
  const radius = (r.limits && r.limits.footprint_m) || 0.105;
  circle(r.pose.x, r.pose.y, radius, color, "#111");
  const [px, py] = toCanvas(r.pose.x, r.pose.y);
  const [hx, hy] = toCanvas(r.pose.x + radius * 1.6 * Math.cos(r.pose.yaw),
                            r.pose.y + radius * 1.6 * Math.sin(r.pose.yaw));
  ctx.strokeStyle = "#111";
  ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(hx, hy); ctx.stroke();
  ctx.fillStyle = "#111";
  ctx.font = "12px system-ui";
  ctx.fillText(id, px + 10, py - 10);
  state.drawn[id] = { x: r.pose.x, y: r.pose.y, px, py, color };
}

function draw() {
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (state.gridImage) {
    const m = state.world.map;
    const [x0, y1] = toCanvas(m.origin[0], m.origin[1] + m.height * m.resolution);
    const { s } = transform();
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(state.gridImage, x0, y1, m.width * m.resolution * s, m.height * m.resolution * s);
  }
  for (const c of state.world.chargers) {
    circle(c.x, c.y, c.radius_m, "rgba(64, 192, 87, 0.25)", "#2f9e44");
    const [px, py] = toCanvas(c.x, c.y);
    ctx.fillStyle = "#2f9e44";
    ctx.font = "bold 14px system-ui";
    ctx.fillText("⚡", px - 5, py + 5);
  }
  for (const z of state.world.zones || []) drawZone(z);
  drawDraft();
  for (const id of Object.keys(state.robots).sort()) drawRobot(id, state.robots[id]);
  drawPlacing();
  state.frames += 1;
}

// -- zones: keepout red, speed limit amber; the one being drawn dashed ----------------------
function polygonPath(points) {
  ctx.beginPath();
  points.forEach(([x, y], i) => {
    const [px, py] = toCanvas(x, y);
    if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
  });
}

function drawZone(z) {
  const keepout = z.kind === "keepout";
  polygonPath(z.xs.map((x, i) => [x, z.ys[i]]));
  ctx.closePath();
  ctx.fillStyle = keepout ? "rgba(224, 49, 49, 0.22)" : "rgba(245, 159, 0, 0.2)";
  ctx.strokeStyle = keepout ? "#c92a2a" : "#e67700";
  ctx.lineWidth = 1.5;
  ctx.fill();
  ctx.stroke();
  const [px, py] = toCanvas(Math.min(...z.xs), Math.max(...z.ys));
  ctx.fillStyle = ctx.strokeStyle;
  ctx.font = "11px system-ui";
  const label = keepout ? z.name : `${z.name} ≤ ${z.max_speed_mps} m/s`;
  ctx.fillText(z.robot_id ? `${label} (${z.robot_id})` : label, px + 3, py + 12);
}

function drawDraft() {
  const points = state.drawing;
  if (!points || !points.length) return;
  polygonPath(points);
  ctx.setLineDash([5, 4]);
  ctx.strokeStyle = "#1d2430";
  ctx.lineWidth = 1.5;
  ctx.stroke();
  ctx.setLineDash([]);
  for (const [x, y] of points) circle(x, y, 0.04, "#1d2430", "#1d2430");
}

function renderZones() {
  const list = $("zones");
  list.replaceChildren();
  for (const z of state.world.zones || []) {
    const cap = z.kind === "keepout" ? "keepout" : `≤ ${z.max_speed_mps} m/s`;
    const who = z.robot_id || "all robots";
    const li = el("li");
    li.append(el("span", {}, `${z.name}: ${cap}, ${who}, ${z.xs.length} vertices`));
    const remove = el("button", { title: `remove zone ${z.name}` }, "Remove");
    remove.onclick = async () => {
      try {
        await call("DELETE", `/api/zones/${encodeURIComponent(z.name)}`);
        say(`zone ${z.name} removed`, true);
      } catch (err) { say(`zone not removed: ${err.message}`, false); }
    };
    li.append(remove);
    list.append(li);
  }
  if (!list.children.length) list.append(el("li", {}, "no zones"));
}

function drawingMode(points) {
  state.drawing = points;
  const on = points !== null;
  $("zone-add").disabled = !on;
  $("zone-discard").disabled = !on;
  $("zone-draw").disabled = on;
  $("zone-hint").textContent = on
    ? `click the map to add vertices (${points.length} so far), then Add zone` : "";
  $("hint").hidden = on;
  draw();
}

// -- panels --------------------------------------------------------------------------------
function renderRobots() {
  const list = $("robots");
  list.replaceChildren();
  for (const id of Object.keys(state.robots).sort()) {
    const r = state.robots[id];
    const li = el("li", { "data-robot": id });
    const sw = el("span", { class: "swatch" });
    sw.style.background = colorOf(id);
    li.append(sw);
    const batt = r.battery ? `${fmt(r.battery.percentage, 1)}%${r.battery.charging ? " ⚡" : ""}` : "-";
    const code = r.strategy ? r.strategy.code : "-";
    li.append(`${id}  ${code}  battery ${batt}`);
    if (id === state.selected) li.classList.add("selected");
    li.onclick = () => { state.selected = id; renderAll(); };
    list.append(li);
  }
}

function renderSelected() {
  const id = state.selected;
  const r = state.robots[id];
  $("sel-robot").textContent = id || "-";
  $("hint-robot").textContent = id || "the robot";
  const facts = $("robot-facts");
  facts.replaceChildren();
  if (!r) return;
  const rows = [
    ["pose", r.pose ? `(${fmt(r.pose.x)}, ${fmt(r.pose.y)}) yaw ${fmt(r.pose.yaw)} · sim ${fmt(r.pose.stamp, 1)} s` : "-"],
    ["speed", r.pose ? `${fmt(r.pose.linear)} m/s, ${fmt(r.pose.angular)} rad/s` : "-"],
    ["goal", r.goal ? `${r.goal.id} (${fmt(r.goal.x)}, ${fmt(r.goal.y)})${r.goal.yaw === null || r.goal.yaw === undefined ? "" : " facing " + fmt(r.goal.yaw * 180 / Math.PI, 0) + "°"} ${r.goal.status}${r.goal.reason ? ": " + r.goal.reason : ""}` : "-"],
    ["route", r.route && r.route.length ? r.route.map((w) => `${w.seq} ${w.status}`).join(", ") : "-"],
    ["strategy", r.strategy ? `${r.strategy.code} (${r.strategy.source})${r.strategy.resume_code ? " resumes " + r.strategy.resume_code : ""}` : "-"],
    ["battery", r.battery ? `${fmt(r.battery.percentage, 2)}% ${r.battery.charging ? "charging" : ""}` : "-"],
    ["path", r.path ? `${r.path.target}, ${r.path.xs.length} points, ${fmt(r.path.length_m)} m` : "-"],
  ];
  for (const [k, v] of rows) facts.append(el("dt", {}, k), el("dd", { "data-fact": k }, v));
  const d = r.decision;
  const box = $("decision");
  box.textContent = d
    ? `#${d.id} · ${d.source || "stop"} · v ${fmt(d.linear)} w ${fmt(d.angular)} · ${d.reason || ""}`
    : "no decision yet";
  box.dataset.decision = d ? d.id : "";
  const body = $("weighed").querySelector("tbody");
  body.replaceChildren();
  for (const rec of (d && d.considered) || []) {
    const tr = el("tr", rec.id === d.recommendation_id ? { class: "won" } : {});
    for (const v of [rec.source, rec.priority, fmt(rec.linear), fmt(rec.angular), rec.reason || ""]) {
      tr.append(el("td", {}, String(v)));
    }
    body.append(tr);
  }
  const select = $("strategy-select");
  if (r.strategy && document.activeElement !== select && !select.dataset.touched) {
    select.value = r.strategy.code;
  }
}

function renderStrategies() {
  const select = $("strategy-select");
  const current = select.value;
  // a strategy whose row the dashboard cannot draw is listed, marked, and not offered
  select.replaceChildren(...state.strategies.map((s) => s.unreadable
    ? el("option", { value: s.code, disabled: "", title: s.unreadable }, `${s.code} (unreadable)`)
    : el("option", { value: s.code, title: s.description || "" }, s.code)));
  if (current) select.value = current;
}

function renderTimeline() {
  const list = $("timeline");
  list.replaceChildren();
  for (const e of state.timeline.slice(-150).reverse()) {
    const li = el("li", { "data-kind": e.kind });
    const when = new Date(e.t * 1000).toLocaleTimeString();
    li.append(el("span", { class: `kind ${e.kind}` }, e.kind), `${when} ${e.robot} · ${e.text}`);
    if (e.ref && e.ref.table === "system_command") {
      // a system command is a decision too: its provenance leads to the battery row
      li.classList.add("clickable");
      li.title = "click for its provenance";
      li.onclick = async () => {
        try { showProvenance(await call("GET", `/api/system-commands/${e.ref.id}`)); }
        catch (err) { say(`provenance: ${err.message}`, false); }
      };
    }
    list.append(li);
  }
}

function renderAll() {
  if (!state.selected || !state.robots[state.selected]) {
    state.selected = Object.keys(state.robots).sort()[0] || null;
  }
  renderRobots();
  renderSelected();
  renderZones();
}

// -- the websocket -------------------------------------------------------------------------
function onMessage(msg) {
  if (msg.type === "snapshot") {
    state.world = msg.world;
    state.robots = msg.robots;
    state.strategies = msg.strategies;
    state.timeline = msg.timeline;
    buildGrid();
    renderStrategies();
    renderTimeline();
  } else if (msg.type === "world") {
    state.world = msg.world;
    buildGrid();
  } else if (msg.type === "strategies") {
    state.strategies = msg.strategies;
    renderStrategies();
  } else if (msg.type === "robots") {
    Object.assign(state.robots, msg.robots);
  } else if (msg.type === "timeline") {
    state.timeline.push(...msg.events);
    state.timeline = state.timeline.slice(-300);
    renderTimeline();
  }
  $("world-name").textContent = state.world.map ? `world ${state.world.map.map_id}` : "";
  renderAll();
  draw();
}

function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.onopen = () => { state.connected = true; status("live", true); };
  ws.onmessage = (ev) => onMessage(JSON.parse(ev.data));
  ws.onclose = () => {
    state.connected = false;
    status("disconnected: retrying…", false);
    setTimeout(connect, 1000);
  };
}

function status(text, good) {
  const s = $("connection");
  s.textContent = text;
  s.className = good ? "good" : "bad";
}

// -- writes --------------------------------------------------------------------------------
function say(text, ok) {
  const m = $("message");
  m.textContent = text;
  m.className = ok ? "ok" : "error";
}

async function call(method, url, body) {
  const response = await fetch(url, {
    method,
    headers: { "Content-Type": "application/json" },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const data = await response.json().catch(() => ({ error: response.statusText }));
  if (!response.ok) throw new Error(`${response.status}: ${data.error || response.statusText}`);
  return data;
}

function canvasPoint(ev) {
  const rect = canvas.getBoundingClientRect();
  return [(ev.clientX - rect.left) * (canvas.width / rect.width),
          (ev.clientY - rect.top) * (canvas.height / rect.height)];
}

const DRAG_PX = 8; // a press that moves further than this sets a heading

// Click: a goal there. Press and drag: a goal there facing the way dragged. With Shift: a
// waypoint of a route instead, sent (in order) with the next goal; Escape forgets them.
async function place(press, release, shift) {
  const robot = state.selected;
  if (!robot) return say("no robot to send", false);
  const [x, y] = toWorld(press[0], press[1]);
  const pose = { x: Math.round(x * 100) / 100, y: Math.round(y * 100) / 100 };
  const dx = release[0] - press[0], dy = release[1] - press[1];
  if (Math.hypot(dx, dy) > DRAG_PX) pose.yaw = Math.round(Math.atan2(-dy, dx) * 1000) / 1000;
  if (shift) {
    state.route.push(pose);
    draw();
    return say(`waypoint ${state.route.length} placed: click (or drag) without Shift for the goal; Escape forgets them`, true);
  }
  const body = state.route.length ? { ...pose, waypoints: state.route } : pose;
  try {
    const g = await call("POST", `/api/robots/${robot}/goal`, body);
    const facing = g.yaw === null || g.yaw === undefined ? "" : ` facing ${fmt(g.yaw * 180 / Math.PI, 0)}°`;
    const through = g.waypoints ? ` through ${g.waypoints} waypoint(s)` : "";
    say(`${robot}: goal ${g.goal_id} set to (${fmt(g.x)}, ${fmt(g.y)})${facing}${through}`, true);
    state.route = [];
  } catch (err) { say(`goal refused: ${err.message}`, false); }
  draw();
}

canvas.addEventListener("mousedown", (ev) => {
  state.press = canvasPoint(ev);
  state.dragTo = null;
  state.dragged = false;
});

canvas.addEventListener("mousemove", (ev) => {
  if (!state.press) return;
  const p = canvasPoint(ev);
  if (Math.hypot(p[0] - state.press[0], p[1] - state.press[1]) > DRAG_PX) {
    state.dragTo = p;
    draw();
  }
});

canvas.addEventListener("mouseup", async (ev) => {
  const press = state.press;
  state.press = state.dragTo = null;
  if (!press) return;
  const release = canvasPoint(ev);
  if (Math.hypot(release[0] - press[0], release[1] - press[1]) <= DRAG_PX) return; // a click
  if (state.drawing) return; // drawing a zone: vertices are clicks
  state.dragged = true; // the click event that follows is this drag's, not a goal
  await place(press, release, ev.shiftKey);
});

canvas.addEventListener("click", async (ev) => {
  if (state.dragged) { state.dragged = false; return; }
  const p = canvasPoint(ev);
  if (state.drawing) { // a zone's next vertex, not a goal
    const [x, y] = toWorld(p[0], p[1]);
    return drawingMode([...state.drawing, [Math.round(x * 100) / 100, Math.round(y * 100) / 100]]);
  }
  await place(p, p, ev.shiftKey);
});

document.addEventListener("keydown", (ev) => {
  if (ev.key === "Escape" && state.route.length) {
    state.route = [];
    draw();
    say("waypoints forgotten", true);
  }
});

$("zone-draw").addEventListener("click", () => drawingMode([]));
$("zone-discard").addEventListener("click", () => drawingMode(null));
$("zone-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const form = ev.target;
  const points = state.drawing || [];
  const body = {
    name: form.elements.namedItem("name").value.trim(),
    kind: form.elements.namedItem("kind").value,
    xs: points.map((p) => p[0]),
    ys: points.map((p) => p[1]),
  };
  if (body.kind === "speed_limit") {
    body.max_speed_mps = Number(form.elements.namedItem("max_speed_mps").value);
  }
  try {
    await call("POST", "/api/zones", body);
    say(`zone ${body.name} added (${body.kind})`, true);
    drawingMode(null);
  } catch (err) { say(`zone refused: ${err.message}`, false); }
});

$("strategy-select").addEventListener("change", (ev) => { ev.target.dataset.touched = "1"; });

$("strategy-set").addEventListener("click", async () => {
  const robot = state.selected;
  const select = $("strategy-select");
  try {
    const v = await call("POST", `/api/robots/${robot}/strategy`, { code: select.value });
    say(`${robot}: ${v.code} ${v.status}${v.reason ? ": " + v.reason : ""}`, v.status !== "rejected");
  } catch (err) { say(`strategy refused: ${err.message}`, false); }
  delete select.dataset.touched;
});

$("goal-cancel").addEventListener("click", async () => {
  const robot = state.selected;
  try {
    const c = await call("DELETE", `/api/robots/${robot}/goal`);
    say(c.cancelled ? `${robot}: goal ${c.cancelled} cancelled` : `${robot}: no active goal`, true);
  } catch (err) { say(`cancel refused: ${err.message}`, false); }
});

$("decision").addEventListener("click", async () => {
  const id = $("decision").dataset.decision;
  if (!id) return;
  try {
    showProvenance(await call("GET", `/api/decisions/${id}`));
  } catch (err) { say(`provenance: ${err.message}`, false); }
});

$("provenance-close").addEventListener("click", () => { $("provenance").hidden = true; });

function showProvenance(p) {
  const body = $("provenance-body");
  body.replaceChildren();
  const d = p.decision;
  const what = p.table === "system_command"
    ? `${d.command}, ${d.status}${d.status_reason ? " (" + d.status_reason + ")" : ""}`
    : `${d.source || "stop"}, v ${fmt(d.linear_mps)} w ${fmt(d.angular_rps)}`;
  body.append(el("p", {}, `${p.table} ${d.id} at sim ${fmt(d.stamp, 2)} s: ${what}. ` +
    `${d.reason || ""}` + (d.safety ? ` Safety layer: ${d.safety}` : "")));
  for (const rec of p.recommendations) {
    body.append(el("h3", {}, `${rec.won ? "★ won: " : ""}recommendation ${rec.id} from ${rec.source} ` +
      `(priority ${rec.priority})`));
    body.append(el("p", {}, rec.reason || ""));
    for (const src of rec.rows) {
      body.append(el("div", {}, `← ${src.table} ${src.id}`));
      body.append(el("pre", {}, src.row ? JSON.stringify(src.row) : src.note));
    }
  }
  if (p.missing_recommendations.length) {
    body.append(el("p", {}, `not in the table any more: ${p.missing_recommendations.join(", ")}`));
  }
  $("provenance").hidden = false;
}

async function loadScenarios() {
  try {
    const data = await call("GET", "/api/strategies");
    const planner = document.querySelector("#strategy-form select[name=planner_scenario]");
    planner.replaceChildren(el("option", { value: "" }, "(none: stand still)"),
      ...data.scenarios.planner.map((n) => el("option", { value: n }, n)));
    const box = $("controller-choices");
    for (const n of data.scenarios.controller) {
      const label = el("label");
      label.append(el("input", { type: "checkbox", name: "controller", value: n }), ` ${n}`);
      box.append(label);
    }
  } catch (err) { say(`cannot list scenarios: ${err.message}`, false); }
}

$("strategy-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const form = ev.target;
  let params;
  try { params = JSON.parse(form.params.value || "{}"); } catch (err) {
    return say(`params: not JSON (${err.message})`, false);
  }
  const body = {
    code: form.code.value.trim().toUpperCase(),
    planner_scenario: form.planner_scenario.value || null,
    controller_scenarios: [...form.querySelectorAll("input[name=controller]:checked")].map((c) => c.value),
    params,
    description: form.description.value,
  };
  try {
    const r = await call("POST", "/api/strategies", body);
    say(`strategy ${r.code} added`, true);
    form.code.value = "";
  } catch (err) { say(`strategy refused: ${err.message}`, false); }
});

loadScenarios();
connect();
