// The MESP Cell console page: the queue, live progress over the WebSocket, the 3D preview,
// history, e-stop. Talks only to the console node's API (same origin); no external resource.
"use strict";

const $ = (id) => document.getElementById(id);
const state = { jobs: [], live: null, selected: null, preview: null, previewId: null,
  dismissed: new Set(), seenFailed: new Set(), cell: null };
// measurements read by the browser tests: progress messages seen and their delay (s)
window.liveStats = { messages: 0, progress: 0, delays: [], lastSeq: -1 };

function token() { return localStorage.getItem("mespToken") || ""; }

async function api(path, opts = {}, retried = false) {
  const headers = Object.assign({}, opts.headers || {});
  if (token()) headers["Authorization"] = "Bearer " + token();
  const res = await fetch(path, Object.assign({}, opts, { headers }));
  if (res.status === 401 && !retried) {
    const t = window.prompt("This console needs its access token ($MESP_HOME/console/token):");
    if (t) { localStorage.setItem("mespToken", t.trim()); return api(path, opts, true); }
  }
  let body = null;
  try { body = await res.json(); } catch (e) { body = null; }
  if (!res.ok) throw new Error((body && body.detail) || res.statusText);
  return body;
}

function hmm(s) {
  if (s === null || s === undefined || !isFinite(s)) return "-";
  const m = Math.ceil(Math.max(s, 0) / 60);
  return Math.floor(m / 60) + ":" + String(m % 60).padStart(2, "0");
}
function clock(t) { return new Date(t * 1000).toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" }); }
function fmt(x, d = 1) { return x === null || x === undefined ? "-" : Number(x).toFixed(d); }
function esc(s) { const d = document.createElement("div"); d.textContent = String(s); return d.innerHTML; }

// -- live stream -------------------------------------------------------------------------
function connect() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${proto}://${location.host}/api/live?token=${encodeURIComponent(token())}`);
  ws.onopen = () => { $("link").textContent = "live"; };
  ws.onclose = (ev) => {
    $("link").textContent = "reconnecting...";
    if (ev.code === 4401) {
      const t = window.prompt("This console needs its access token ($MESP_HOME/console/token):");
      if (t) localStorage.setItem("mespToken", t.trim());
    }
    setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    window.liveStats.messages++;
    if (msg.type === "live") onLive(msg);
    else if (msg.type === "jobs") onJobs(msg.jobs);
  };
}

function onLive(msg) {
  state.live = msg;
  const st = window.liveStats;
  if (msg.job && msg.seq !== st.lastSeq) {
    const first = st.lastSeq === -1;  // the console's last message, maybe from long ago
    st.lastSeq = msg.seq;
    if (!first) st.progress++;
    if (!first) st.delays.push(Date.now() / 1000 - msg.job.progress_t);
    if (st.delays.length > 1000) st.delays.shift();
  }
  $("nodes").innerHTML = ["supervisor", "robot", "extruder", "slicer", "planner"].map(
    (n) => `<span class="${msg.alive.includes(n) ? "up" : ""}">${n}</span>`).join("");
  const ext = msg.extruder || {};
  if (ext.estop) showEstop("E-STOP latched" + (state.estopText ? ": " + state.estopText : ""));
  else if (!state.estopPending) showEstop("");
  const j = msg.job;
  const cur = state.jobs.find((x) => ["printing", "paused", "interrupted"].includes(x.state));
  if (cur && (!j || cur.id !== j.job_id)) {  // stopped before its first progress message
    $("cur-id").textContent = cur.id;
    $("cur-state").textContent = cur.state;
    $("bar-fill").style.width = cur.percent.toFixed(1) + "%";
    $("bar-text").textContent = `${cur.percent.toFixed(1)} % of the time`;
    $("cur-layer").textContent = cur.layers ? `${cur.layer >= 0 ? cur.layer + 1 : "-"} / ${cur.layers}` : "-";
    $("cur-ink").textContent = `${fmt(cur.ink_mm3, 0)} mm³`;
    for (const id of ["cur-eta", "cur-finish", "cur-track", "cur-clear"]) $(id).textContent = "-";
    return;
  }
  if (!j) return;
  const printing = j.state === "printing";
  $("cur-id").textContent = j.job_id;
  $("cur-state").textContent = j.state;
  const pct = j.percent_time || 0;
  $("bar-fill").style.width = pct.toFixed(1) + "%";
  $("bar-text").textContent = `${pct.toFixed(1)} % of the time` + (j.percent_ink !== null && j.percent_ink !== undefined ? ` - ${j.percent_ink.toFixed(1)} % of the ink` : "");
  $("cur-layer").textContent = `${j.layer + 1} / ${j.layers}`;
  $("cur-eta").textContent = printing ? hmm(j.eta_s) : "-";
  $("cur-finish").textContent = printing ? clock(Date.now() / 1000 + j.eta_s) : "-";
  $("cur-ink").textContent = `${fmt(j.ink_mm3, 0)} / ${fmt(j.ink_planned_mm3, 0)} mm³`;
  $("cur-rate").textContent = `${fmt(ext.rate, 2)} (${fmt(ext.rate_set, 2)}) mm³/s`;
  $("cur-track").textContent = j.tracking_error_deg === undefined ? "-" : `${fmt(j.tracking_error_deg, 2)}°`;
  $("cur-clear").textContent = j.min_clearance_mm === null ? "-" : `${fmt(j.min_clearance_mm, 1)} mm`;
  const faults = (ext.faults || []).concat(msg.robot && msg.robot.protective_stop ? ["protective stop"] : []);
  $("cur-faults").textContent = faults.length ? faults.join(", ") : "none";
  if (state.previewId !== j.job_id && printing) selectJob(j.job_id);
  if (state.preview && printing) markLayer(j.layer);
}

function showEstop(text) {
  $("estop-banner").classList.toggle("hidden", !text);
  if (text) $("estop-text").textContent = text;
}

// -- queue, alerts, history ----------------------------------------------------------------
function onJobs(jobs) {
  state.jobs = jobs;
  const body = $("queue").querySelector("tbody");
  const open = jobs.filter((j) => !j.final);
  body.innerHTML = open.map((j) => {
    let act = "";
    if (j.state === "ready_check" && !j.ready_confirmed) act = `<button class="go" data-act="ready" data-id="${j.id}">Tank ready</button>`;
    if (j.state === "printing") act = `<button data-act="pause" data-id="${j.id}">Pause</button>`;
    if (j.state === "paused" || j.state === "interrupted") act = `<button data-act="resume" data-id="${j.id}">Resume</button>`;
    act += ` <button class="warn" data-act="abort" data-id="${j.id}">Abort</button>`;
    return `<tr data-id="${j.id}" class="${j.id === state.selected ? "sel" : ""}"><td>${esc(j.id)}</td><td><span class="state">${j.state}</span></td>` +
      `<td>${j.layers ? `${j.layer + 1}/${j.layers} - ${j.percent.toFixed(1)} %` : "-"}</td><td>${act}</td></tr>`;
  }).join("") || `<tr><td colspan="4" class="muted">no jobs queued</td></tr>`;
  alerts(jobs);
  if (state.live) onLive(state.live);  // the panel shows the store's state at once
  loadHistory();
  if (state.selected) loadEvents(state.selected);
  const sel = jobs.find((j) => j.id === state.selected);
  if (!state.preview && sel && !["submitted"].includes(sel.state)) loadPreview(sel.id);
  if (!state.selected && jobs.length) selectJob(jobs[jobs.length - 1].id);
}

function alerts(jobs) {
  const out = [];
  for (const j of jobs) {
    if (j.state === "ready_check" && !j.ready_confirmed) {
      out.push(`<div class="banner wait" data-alert="ready">Job ${esc(j.id)} waits for the operator: remove the last part, check the gel level, then confirm. <button class="go" data-act="ready" data-id="${j.id}">Tank ready - start ${esc(j.id)}</button></div>`);
    }
    if (j.state === "failed" && !state.dismissed.has(j.id) && Date.now() / 1000 - j.updated < 86400) {
      out.push(`<div class="banner danger" data-alert="failed">Job ${esc(j.id)} failed: ${esc(j.reason)} <button data-dismiss="${j.id}">Dismiss</button></div>`);
    }
    if (j.state === "interrupted" && !state.dismissed.has(j.id)) {
      out.push(`<div class="banner danger" data-alert="interrupted">Job ${esc(j.id)} stopped: ${esc(j.reason)} <button data-dismiss="${j.id}">Dismiss</button></div>`);
    }
  }
  $("alerts").innerHTML = out.join("");
  document.title = (out.length ? "(!) " : "") + "MESP Cell console";
}

async function loadHistory() {
  try {
    const rows = await api("/api/history");
    $("history").querySelector("tbody").innerHTML = rows.slice(0, 20).map((j) =>
      `<tr data-id="${j.id}"><td>${esc(j.id)}</td><td><span class="state">${j.result}</span></td><td>${j.duration_s === null ? "-" : hmm(j.duration_s)}</td>` +
      `<td>${fmt(j.ink_mm3, 0)} mm³</td><td>${clock(j.updated)}</td></tr>`).join("");
  } catch (e) { /* shown by the next call */ }
}

async function loadEvents(id) {
  try {
    const job = await api(`/api/jobs/${encodeURIComponent(id)}`);
    $("ev-id").textContent = id;
    $("events").innerHTML = job.history.map((e) =>
      `<li>${new Date(e.t * 1000).toLocaleTimeString()} ${e.from && e.from !== e.to ? esc(e.from) + " &rarr; " : ""}<b>${esc(e.to)}</b> ${esc(e.reason)}</li>`).join("");
  } catch (e) { $("events").innerHTML = `<li>${esc(e.message)}</li>`; }
}

function selectJob(id) {
  state.selected = id;
  document.querySelectorAll("#queue tr").forEach((tr) => tr.classList.toggle("sel", tr.dataset.id === id));
  loadEvents(id);
  loadPreview(id);
  loadFigures(id);
}

// -- preview ---------------------------------------------------------------------------------
async function loadPreview(id) {
  if (state.previewId === id && state.preview) return;
  try {
    const pv = await api(`/api/jobs/${encodeURIComponent(id)}/preview`);
    state.preview = pv; state.previewId = id;
    $("pv-id").textContent = id;
    const slider = $("pv-layer");
    slider.max = Math.max(pv.layers - 1, 0);
    slider.value = slider.max;
    drawPreview();
  } catch (e) {
    state.preview = null; state.previewId = null;
    $("pv-id").textContent = `${id}: ${e.message}`;
  }
}

function drawPreview() {
  const pv = state.preview;
  if (!pv) return;
  const upto = Number($("pv-layer").value);
  $("pv-layer-n").textContent = `${upto + 1} / ${pv.layers}`;
  const by = $("pv-colour").value;
  const keep = (i) => pv.layer[i] !== null && pv.layer[i] <= upto;
  const x = [], y = [], z = [], c = [];
  for (let i = 0; i < pv.x.length; i++) {
    if (pv.x[i] === null || !keep(i)) { if (x.length && x[x.length - 1] !== null) { x.push(null); y.push(null); z.push(null); c.push(null); } continue; }
    x.push(pv.x[i]); y.push(pv.y[i]); z.push(pv.z[i]); c.push(pv[by][i]);
  }
  const unit = { layer: "layer", width: "width (mm)", speed: "speed (mm/s)" }[by];
  const trace = { type: "scatter3d", mode: "lines", x, y, z,
    line: { color: c, colorscale: "Viridis", width: 3, showscale: true, colorbar: { title: { text: unit } } },
    hoverinfo: "skip" };
  // true proportions in x and y; a flat part keeps some height so its layers stay apart
  const span = (a) => {
    let lo = Infinity, hi = -Infinity;
    for (const q of a) if (q !== null) { if (q < lo) lo = q; if (q > hi) hi = q; }
    return hi > lo ? hi - lo : 1;
  };
  const dx = span(pv.x), dy = span(pv.y), dz = span(pv.z), m = Math.max(dx, dy, dz, 1e-6);
  const layout = { margin: { l: 0, r: 0, t: 0, b: 0 }, uirevision: "keep",
    scene: { aspectmode: "manual", aspectratio: { x: dx / m, y: dy / m, z: Math.max(dz / m, 0.3) },
      camera: { eye: { x: 1.4, y: -1.4, z: 1.0 } } } };
  Plotly.react("plot", [trace], layout, { displaylogo: false, responsive: true });
  $("plot").dataset.points = String(x.filter((v) => v !== null).length);
}

function markLayer(layer) {
  // "follow the print": the preview shows the layers printed so far and the current one
  const slider = $("pv-layer");
  if (!$("pv-follow").checked || state.previewId !== currentJob() || Number(slider.value) === layer) return;
  slider.value = Math.max(layer, 0);
  drawPreview();
}

async function loadFigures(id) {
  try {
    const names = await api(`/api/jobs/${encodeURIComponent(id)}/figures`);
    $("figures").innerHTML = names.map((n) =>
      `<a href="/api/jobs/${encodeURIComponent(id)}/figures/${encodeURIComponent(n)}" target="_blank"><img alt="${esc(n)}" title="${esc(n)}" src="/api/jobs/${encodeURIComponent(id)}/figures/${encodeURIComponent(n)}"></a>`).join("");
  } catch (e) { $("figures").innerHTML = ""; }
}

// -- actions ---------------------------------------------------------------------------------
async function act(verb, id) {
  if (verb === "abort" && !window.confirm(`Abort ${id}? The nozzle retracts and goes home; the job cannot be resumed.`)) return;
  try {
    await api(`/api/jobs/${encodeURIComponent(id)}/${verb}`, { method: "POST" });
    flash(`${verb}: ${id}`, "info");
  } catch (e) { flash(e.message, "danger"); }
}

function flash(text, kind) {
  const div = document.createElement("div");
  div.className = `banner ${kind}`;
  div.dataset.flash = "1";
  div.textContent = text;
  document.body.insertBefore(div, document.querySelector("main"));
  setTimeout(() => div.remove(), kind === "danger" ? 10000 : 3000);
}

document.addEventListener("click", (ev) => {
  const b = ev.target.closest("button[data-act]");
  if (b) { act(b.dataset.act, b.dataset.id); return; }
  const d = ev.target.closest("button[data-dismiss]");
  if (d) { state.dismissed.add(d.dataset.dismiss); alerts(state.jobs); return; }
  const tr = ev.target.closest("tr[data-id]");
  if (tr) selectJob(tr.dataset.id);
});

function currentJob() {
  const j = state.jobs.find((x) => ["printing", "paused", "interrupted"].includes(x.state));
  return j ? j.id : (state.live && state.live.job ? state.live.job.job_id : null);
}
$("btn-pause").onclick = () => { const id = currentJob(); if (id) act("pause", id); };
$("btn-resume").onclick = () => { const id = currentJob(); if (id) act("resume", id); };
$("btn-abort").onclick = () => { const id = currentJob(); if (id) act("abort", id); };

$("estop").onclick = async () => {
  state.estopPending = true;
  showEstop("E-stop sent...");
  try {
    const r = await api("/api/estop", { method: "POST" });
    state.estopText = r.lines.join(" - ");
    showEstop((r.confirmed ? "E-STOP: " : "E-STOP NOT CONFIRMED - use the hardware e-stop: ") + state.estopText);
  } catch (e) { showEstop("E-stop failed: " + e.message + " - use the hardware e-stop"); }
  state.estopPending = false;
};
$("estop-reset").onclick = async () => {
  try { await api("/api/estop/reset", { method: "POST" }); state.estopText = ""; showEstop(""); flash("e-stop cleared", "info"); }
  catch (e) { flash(e.message, "danger"); }
};

$("submit-form").onsubmit = async (ev) => {
  ev.preventDefault();
  const form = new FormData();
  form.append("model", $("model").files[0]);
  if ($("jobfile").files[0]) form.append("job", $("jobfile").files[0]);
  $("submit-msg").textContent = "uploading...";
  try {
    const job = await api("/api/jobs", { method: "POST", body: form });
    $("submit-msg").textContent = `queued ${job.id}`;
    selectJob(job.id);
  } catch (e) { $("submit-msg").textContent = e.message; }
};
// The twin drawn at the robot's pose, fetched with the token like every call, while shown.
async function twinFrame() {
  if (!$("twin-on").checked) return;
  const headers = token() ? { Authorization: "Bearer " + token() } : {};
  try {
    const res = await fetch("/api/twin.png", { headers, cache: "no-store" });
    if (!res.ok) {
      let why = res.statusText;
      try { why = (await res.json()).detail; } catch (e) { /* keep the status text */ }
      $("twin-msg").textContent = why;
      return;
    }
    const url = URL.createObjectURL(await res.blob());
    const img = $("twin-img");
    if (img.src) URL.revokeObjectURL(img.src);
    img.src = url;
    img.classList.remove("hidden");
    $("twin-msg").textContent = "";
    window.liveStats.twinFrames = (window.liveStats.twinFrames || 0) + 1;
  } catch (e) { $("twin-msg").textContent = e.message; }
}
$("twin-on").onchange = twinFrame;
setInterval(twinFrame, 1500);
$("pv-layer").oninput = () => { $("pv-follow").checked = false; drawPreview(); };
$("pv-colour").onchange = drawPreview;

api("/api/cell").then((c) => { $("cell").textContent = c.cell; }).catch((e) => flash(e.message, "danger"));
connect();
