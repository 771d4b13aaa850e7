// The console page: polls /api/state, fetches the shown view's newest JPEG one at a time (the server bounds
// the rate), draws Af over time, and sends the operator's changes with the token (none: view only).
"use strict";

const TOKEN = window.CONSOLE_TOKEN || new URLSearchParams(location.search).get("token") || "";
const HEADERS = TOKEN ? { "X-Console-Token": TOKEN } : {};
const $ = (id) => document.getElementById(id);
let view = "area";
let state = null;
let editing = null; // a setting the operator is changing: not overwritten by the next poll
let drawing = false;
let dragStart = null;
let series = { run: null, appended: 0, points: [] }; // the Af series as far as this page has it
const shownText = new Map(); // what each element shows: a poll that changes nothing touches no element

// A page nobody sees (a tab in the background, a minimised window) asks for nothing: its images and polls
// would cost the measuring machine CPU for no one. It catches up when shown again.
function whileHidden() {
  if (!document.hidden) return Promise.resolve();
  return new Promise((shown) => {
    const back = () => {
      if (document.hidden) return;
      document.removeEventListener("visibilitychange", back);
      shown();
    };
    document.addEventListener("visibilitychange", back);
  });
}

// An element's text or children only when they differ from what it shows: every change costs the browser
// a layout and a paint, twice a second per page, on the machine that measures.
function setText(id, text) {
  if (shownText.get(id) === text) return;
  shownText.set(id, text);
  $(id).textContent = text;
}

function setList(id, items, tag = "li") {
  const key = JSON.stringify(items);
  if (shownText.get(id) === key) return;
  shownText.set(id, key);
  $(id).replaceChildren(...items.map((item) => {
    const element = document.createElement(tag); element.textContent = item; return element;
  }));
}

function setClass(id, name) {
  if ($(id).className !== name) $(id).className = name;
}

function say(text, failed) {
  const status = $("status");
  status.textContent = text;
  status.className = failed ? "failed" : "";
}

async function post(path, body) {
  try {
    const answer = await fetch(path, {
      method: "POST", headers: { ...HEADERS, "Content-Type": "application/json" },
      body: JSON.stringify(body || {}),
    });
    const reply = await answer.json();
    say(reply.message || reply.error || answer.statusText, !answer.ok);
    return answer.ok;
  } catch (error) {
    say("the console does not answer: " + error, true);
    return false;
  }
}

// --- the image ------------------------------------------------------------------------------------------
// Drawn into a canvas from a bitmap decoded off the page's main thread: swapping an <img>'s source cost the
// browser about twice the CPU per frame (bench/console_load.py).
async function imageLoop() {
  for (;;) {
    await whileHidden();
    const asked = view;
    const img = $("frame");
    const after = img.dataset.view === asked && img.dataset.frameNumber ? img.dataset.frameNumber : "-1";
    try {
      const answer = await fetch(`/api/frame/${asked}?after=${after}`, { headers: HEADERS });
      if (answer.status === 200 && asked === view) {
        const bitmap = await createImageBitmap(await answer.blob());
        if (img.width !== bitmap.width || img.height !== bitmap.height) {
          img.width = bitmap.width;
          img.height = bitmap.height;
        }
        img.getContext("2d").drawImage(bitmap, 0, 0);
        bitmap.close();
        img.dataset.shown = "1";
        img.dataset.frameNumber = answer.headers.get("X-Frame-Number");
        img.dataset.view = asked;
        img.dataset.frameSize = answer.headers.get("X-Frame-Size");
        $("no-frame").style.display = "none";
      } else if (answer.status === 204 && asked === view) {
        $("no-frame").style.display = "block";
        $("no-frame").textContent = "no image yet on this view";
      }
    } catch (error) {
      $("no-frame").style.display = "block";
      $("no-frame").textContent = "the console does not answer";
    }
    await new Promise((done) => setTimeout(done, 150));
  }
}

function chooseView(next) {
  view = next;
  document.querySelectorAll("button.view").forEach((b) => b.classList.toggle("selected", b.dataset.view === next));
  $("no-frame").style.display = "block";
  $("no-frame").textContent = "waiting for " + next + " images";
  $("frame-note").textContent = {
    area: "the area node's overlay: mask in red, ROI in yellow, targets in green",
    calibration: "the calibration node's feedback: detected corners, coverage, bars, what is still needed",
    camera: "the camera's image as it comes",
  }[next];
}

// --- the ROI, dragged on the image ----------------------------------------------------------------------
function imagePoint(event) {
  const img = $("frame");
  const box = img.getBoundingClientRect();
  return [(event.clientX - box.left) * img.width / box.width,
          (event.clientY - box.top) * img.height / box.height];
}

function drawRectangle(a, b) {
  const canvas = $("roi-canvas");
  const img = $("frame");
  canvas.width = img.dataset.shown ? img.width : 1;
  canvas.height = img.dataset.shown ? img.height : 1;
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (!a || !b) return;
  ctx.strokeStyle = "#ffd60a";
  ctx.lineWidth = Math.max(2, canvas.width / 300);
  ctx.setLineDash([8, 6]);
  ctx.strokeRect(Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.abs(b[0] - a[0]), Math.abs(b[1] - a[1]));
}

function setupRoi() {
  const canvas = $("roi-canvas");
  $("draw-roi").onclick = () => {
    drawing = !drawing;
    canvas.classList.toggle("drawing", drawing);
    $("draw-roi").classList.toggle("drawing", drawing);
    if (drawing) { chooseView("area"); say("drag a rectangle on the image"); }
  };
  canvas.onmousedown = (event) => {
    // before the view's first image has loaded it has no size: a point on it would be read as 0, 0
    if (!$("frame").dataset.shown) { say("no image shown yet: drag again once it is"); return; }
    dragStart = imagePoint(event);
  };
  canvas.onmousemove = (event) => { if (dragStart) drawRectangle(dragStart, imagePoint(event)); };
  canvas.onmouseup = async (event) => {
    if (!dragStart) return;
    const end = imagePoint(event);
    const start = dragStart;
    dragStart = null;
    drawing = false;
    canvas.classList.remove("drawing");
    $("draw-roi").classList.remove("drawing");
    await post("/api/parameters", { roi_drag: { view: "area", start, end } });
    drawRectangle(null, null);
  };
  $("clear-roi").onclick = () => post("/api/parameters", { roi: [0.0] });
}

// --- settings -------------------------------------------------------------------------------------------
const SELECTS = ["threshold_mode", "object", "channel", "area_mode", "tone_curve"];
let thresholdTimer = null;

function setupSettings() {
  const slider = $("threshold");
  slider.oninput = () => {
    editing = "threshold";
    setText("threshold-value", slider.value);
    clearTimeout(thresholdTimer);
    // a fixed threshold: the slider's value is what classifies (otsu would ignore it)
    thresholdTimer = setTimeout(async () => {
      await post("/api/parameters", { threshold: Number(slider.value), threshold_mode: "fixed" });
      editing = null;
    }, 150);
  };
  for (const name of SELECTS) {
    $(name).onchange = async () => { editing = name; await post("/api/parameters", { [name]: $(name).value }); editing = null; };
  }
  for (const name of ["open_px", "close_px"]) {
    $(name).onchange = async () => { editing = name; await post("/api/parameters", { [name]: Number($(name).value) }); editing = null; };
  }
  $("fit").onclick = () => { say("fitting..."); return post("/api/calibration/fit"); };
  $("commit").onclick = () => post("/api/calibration/commit");
  $("discard").onclick = () => post("/api/calibration/discard");
  $("record-start").onclick = () => post("/api/record/start");
  $("record-stop").onclick = () => { say("closing the bag..."); return post("/api/record/stop"); };
  document.querySelectorAll("button.view").forEach((b) => { b.onclick = () => chooseView(b.dataset.view); });
}

function showSettings(parameters, choices) {
  for (const name of SELECTS) {
    const select = $(name);
    if (select.options.length === 0 && choices[name]) {
      for (const choice of choices[name]) select.add(new Option(choice, choice));
    }
    if (editing !== name && parameters[name] !== undefined && select.value !== String(parameters[name])) {
      select.value = parameters[name];
    }
  }
  if (editing !== "threshold" && parameters.threshold !== undefined) {
    if (Number($("threshold").value) !== Number(parameters.threshold)) $("threshold").value = parameters.threshold;
    setText("threshold-value", Number(parameters.threshold).toFixed(0));
  }
  for (const name of ["open_px", "close_px"]) {
    if (editing !== name && parameters[name] !== undefined && document.activeElement !== $(name) &&
        $(name).value !== String(parameters[name])) $(name).value = parameters[name];
  }
  const roi = parameters.roi;
  setText("roi-value", !roi ? "–" : (roi.length === 1 ? "inside the targets" :
    roi.map((v) => Number(v).toFixed(0)).join(", ")));
}

// --- Af -------------------------------------------------------------------------------------------------
function drawChart(points) {
  const canvas = $("af-chart");
  const ctx = canvas.getContext("2d");
  const w = canvas.width, h = canvas.height, left = 64, bottom = 24;
  ctx.clearRect(0, 0, w, h);
  ctx.font = "11px sans-serif";
  ctx.fillStyle = "#555";
  if (points.length === 0) { ctx.fillText("no Af yet", left, h / 2); return; }
  const t0 = points[0][0], t1 = Math.max(points[points.length - 1][0], t0 + 1e-3);
  let lo = Infinity, hi = -Infinity;
  for (const [, a, s] of points) { lo = Math.min(lo, a - s); hi = Math.max(hi, a + s); }
  if (hi - lo < 1e-12) { hi += 1e-6; lo -= 1e-6; }
  const pad = (hi - lo) * 0.08; lo -= pad; hi += pad;
  const x = (t) => left + (t - t0) / (t1 - t0) * (w - left - 8);
  const y = (a) => (h - bottom) - (a - lo) / (hi - lo) * (h - bottom - 8);
  ctx.fillStyle = "#a8dadc88";
  ctx.beginPath();
  points.forEach(([t, a, s], i) => (i ? ctx.lineTo(x(t), y(a + s)) : ctx.moveTo(x(t), y(a + s))));
  for (let i = points.length - 1; i >= 0; i--) ctx.lineTo(x(points[i][0]), y(points[i][1] - points[i][2]));
  ctx.closePath();
  ctx.fill();
  ctx.strokeStyle = "#1d3557";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  points.forEach(([t, a], i) => (i ? ctx.lineTo(x(t), y(a)) : ctx.moveTo(x(t), y(a))));
  ctx.stroke();
  ctx.fillStyle = "#333";
  ctx.fillText((hi * 1e4).toPrecision(5) + " cm²", 2, 12);
  ctx.fillText((lo * 1e4).toPrecision(5) + " cm²", 2, h - bottom);
  ctx.fillText(t0.toFixed(1) + " s", left, h - 6);
  ctx.fillText(t1.toFixed(1) + " s (run time; band: ± 1 std)", w - 190, h - 6);
}

// The points after those the page has (the whole series when `complete`: a new run, or the page fell
// behind), kept to the server's window; whether anything changed.
function mergeSeries(area) {
  const points = area.complete ? area.points : series.points.concat(area.points);
  series = { run: area.run, appended: area.appended, points: points.slice(-area.window) };
  return area.complete || area.points.length > 0;
}

function showArea(area) {
  if (mergeSeries(area)) {
    const points = series.points;
    if (points.length) {
      const [, a, s] = points[points.length - 1];
      setText("af-now", `${(a * 1e4).toFixed(3)} ± ${(s * 1e4).toFixed(3)} cm²  (${a.toExponential(4)} m²)`);
    }
    drawChart(points);
  }
  const f = area.frames;
  const count = (v) => (v === null || v === undefined ? "–" : v);
  setText("frames", `frames measured ${count(f.measured)}, skipped ${count(f.skipped)}, lost ${count(f.lost)}` +
    (area.area_mode ? ` · mode ${area.area_mode}${area.subpixel_applied === false ? " (counted whole pixels)" : ""}` : "") +
    (area.threshold !== null && area.threshold !== undefined ? ` · threshold ${Number(area.threshold).toFixed(1)}` : "") +
    (area.calibrated === false ? " · UNCALIBRATED" : ""));
  const thinned = state && state.thinned && state.thinned.results;
  setText("thinned", thinned ? `the chart shows about ${Math.round(thinned.per_s)} of ` +
    `${Math.round(thinned.rate_hz)} results a second (every one is published and recorded)` : "");
  setList("warnings", area.warnings);
}

// --- calibration and recording ------------------------------------------------------------------------
function showCalibration(calibration) {
  const p = calibration.progress || {};
  const rejected = Object.entries(p.rejected || {}).map(([k, v]) => `${k} ${v}`).join(", ") || "none";
  const served = calibration.served;
  const lines = [
    `views kept ${p.views_kept ?? 0} · frames seen ${p.frames_seen ?? 0} · coverage ${p.coverage !== undefined ? Math.round(p.coverage * 100) + " %" : "–"}`,
    `rejected: ${rejected}`,
    `fit: ${p.fitted ? "yes" : "no"}${p.rms_px ? ", RMS " + p.rms_px.toFixed(4) + " px" : ""}`,
    served ? `served: ${served.model} ${served.width}x${served.height}, fx ${served.fx.toFixed(2)}, fy ${served.fy.toFixed(2)}, cx ${served.cx.toFixed(2)}, cy ${served.cy.toFixed(2)}` : "served: no calibration yet",
  ];
  setList("calibration-figures", lines, "div");
  setText("still-needed", p.still_needed ? "still needed: " + p.still_needed : "");
  setList("calibration-messages", calibration.messages.slice().reverse());
}

function showRecording(recording) {
  if (!recording) { setText("recording", "not recording"); return; }
  const mb = (recording.bytes / 1e6).toFixed(1);
  setText("recording", recording.running && !recording.started ? "starting the recorder..." :
    recording.running ? `recording into ${recording.bag}: ${mb} MB` :
    `last bag ${recording.bag}: ${mb} MB (recorder exit code ${recording.exit_code})`);
}

function showNodes(nodes, access) {
  for (const [key, node] of Object.entries(nodes)) {
    setText("node-" + key, `${node.name} ${node.present ? "up" : "missing"}`);
    setClass("node-" + key, "badge " + (node.present ? "up" : "down"));
  }
  const canChange = access.may_change;
  setText("access", canChange ? "control" : "view only (no token)");
  setClass("access", "badge " + (canChange ? "up" : "viewonly"));
  document.querySelectorAll(".control").forEach((c) => {
    const panel = c.closest("section").id;
    const needs = panel === "calibration-panel" ? nodes.calibration.present :
      (panel === "record-panel" ? true : nodes.area.present);
    const disabled = !canChange || !needs;
    if (c.disabled !== disabled) c.disabled = disabled;
  });
  setText("parameters-note", nodes.area.present ? "" : `(${nodes.area.name} is not running)`);
}

async function stateLoop() {
  for (;;) {
    await whileHidden();
    try {
      const since = series.run === null ? "" : `?run=${series.run}&appended=${series.appended}`;
      const answer = await fetch("/api/state" + since, { headers: HEADERS });
      state = await answer.json();
      showNodes(state.nodes, state.access);
      showArea(state.area);
      showSettings(state.parameters, state.choices);
      showCalibration(state.calibration);
      showRecording(state.recording);
      showLoad(state.load);
      document.body.dataset.polls = String(Number(document.body.dataset.polls || 0) + 1);
    } catch (error) {
      say("the console does not answer: " + error, true);
    }
    await new Promise((done) => setTimeout(done, 1000 * ((state && state.load && state.load.poll_s) || 0.5)));
  }
}

// The console gives way when the measuring machine's cores are busy: fewer images, fewer polls, said here.
function showLoad(load) {
  setText("load-note", load && load.slowed
    ? `images slowed to ${load.images_per_s} a second: the measuring machine's cores are busy ` +
      `(a task waited for a CPU ${Math.round(100 * load.cpu_pressure)} % of the last 10 s)`
    : "");
}

setupSettings();
setupRoi();
chooseView("area");
stateLoop();
imageLoop();
