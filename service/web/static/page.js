// The operator page: a client of the REST API (/api/v1) like any other.
//
// It validates nothing itself: every value goes to the API as typed, and what the API says
// (an RFC 9457 problem: its `detail`; for a 422 its `errors`, each naming its `field`) is shown
// in the message box and next to each field. The token is kept in
// sessionStorage (this browser tab's session); reading needs none. Campaigns and calibration
// jobs are followed through their server-sent events; pose images, plots, the campaign list and
// the calibration come as HTML fragments rendered by the service's templates (/ui/...).
"use strict";

const API = "/api/v1";
const TOKEN_KEY = "toftwin-token";
const CAMPAIGN_TERMINAL = ["completed", "cancelled", "failed"];
const CALIBRATION_TERMINAL = ["done", "failed", "cancelled"];
const RIG_POLL_MS = 2000;

const $ = (sel, root = document) => root.querySelector(sel);
const $$ = (sel, root = document) => Array.from(root.querySelectorAll(sel));

// -- talking to the API -------------------------------------------------------------------------
function token() {
  return sessionStorage.getItem(TOKEN_KEY) || "";
}

async function call(method, path, body) {
  const headers = {};
  if (body !== undefined) headers["Content-Type"] = "application/json";
  if (token()) headers.Authorization = `Bearer ${token()}`;
  let res;
  try {
    res = await fetch(path, {method, headers,
                             body: body === undefined ? undefined : JSON.stringify(body)});
  } catch (err) {
    return {ok: false, status: 0,
            data: {title: "No answer", detail: `the service does not answer (${err})`}};
  }
  const type = res.headers.get("content-type") || "";
  const data = type.includes("json") ? await res.json() : await res.text();
  return {ok: res.ok, status: res.status, data};
}

// A fragment's answers may arrive out of order (a campaign's events ask for the list again while
// the last answer is on its way): only the newest request of a target may fill it.
const fragmentAsked = new WeakMap();
async function fragment(path, target) {
  const asked = (fragmentAsked.get(target) || 0) + 1;
  fragmentAsked.set(target, asked);
  const res = await call("GET", path);
  if (res.ok && fragmentAsked.get(target) === asked) target.innerHTML = res.data;
  return res.ok;
}

// What went wrong, in a sentence: every error of the API is a problem (application/problem+json:
// type, title, status, detail); anything else (a proxy's page) is shown as it came.
function problem(res) {
  if (res.status === 401) {
    return "This needs the token: enter TOFTWIN_TOKEN at the top (kept for this session).";
  }
  const d = res.data || {};
  if (typeof d === "string") return `${res.status}: ${d.slice(0, 300)}`;
  return d.detail || d.title || `${res.status}: ${JSON.stringify(d).slice(0, 300)}`;
}

// The message box keeps the last few messages, newest first (an emergency stop's report and the
// error of the move it interrupted both stay readable).
const MESSAGES_KEPT = 4;

function say(text, kind = "info") {
  const box = $("#message");
  const line = document.createElement("div");
  line.className = `line ${kind}`;
  line.textContent = `${new Date().toLocaleTimeString()}  ${text}`;
  box.prepend(line);
  while (box.childElementCount > MESSAGES_KEPT) box.lastElementChild.remove();
  box.className = `message ${kind}`;
  box.hidden = false;
  clearTimeout(say.timer);
  if (kind === "info") say.timer = setTimeout(() => { box.hidden = true; }, 8000);
}

// What the API said about a form's fields (a 422 problem's `errors`), next to each field (its
// `field` path, else the last or first part of it, else the form's general box).
function showErrors(form, res) {
  $$(".field-error", form).forEach((el) => { el.textContent = ""; });
  if (res.ok) return;
  const errors = res.status === 422 && Array.isArray(res.data.errors) ? res.data.errors : [];
  for (const e of errors) {
    const field = e.field || "body";
    const parts = field.replace(/\[\d+\]/g, "").split(".");
    const keys = [field, parts.join("."), parts[parts.length - 1], parts[0], "body"];
    const box = keys.map((k) => $(`.field-error[data-field="${k}"]`, form)).find(Boolean);
    const message = String(e.message || "");
    const text = message.startsWith(`${field}:`) ? message : `${field}: ${message}`;
    if (box) box.textContent = box.textContent ? `${box.textContent}\n${text}` : text;
  }
  say(problem(res), "error");
}

// A form value as the API should see it: a number when it reads as one, else the text as
// typed (the API then says what is wrong with it); empty: left out.
function value(text) {
  const s = String(text).trim();
  if (s === "") return undefined;
  const n = Number(s);
  return Number.isFinite(n) ? n : s;
}

function list(text) {
  return String(text).split(/[,\s]+/).filter((s) => s !== "");
}

// Turntable angles in the grammar of calibration/angles.py (parse_angles: the server's, the
// authority; this copy gives the form its poses at once, and tests/web checks it against the
// server's): numbers separated by commas and/or spaces, or "from:to:step", the end included when
// a step reaches it (within 1e-9 of a step), each rounded to 1e-9 deg, at most 721 angles. Text
// of neither form is sent as typed, and the API's message says what is wrong with it.
const NUMBER = /^[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$/;
const MAX_ANGLES = 721;

function angles(text) {
  const t = String(text).trim();
  if (t.includes(":")) {
    const parts = t.split(":").map((s) => s.trim());
    if (parts.length !== 3 || !parts.every((s) => NUMBER.test(s))) return [t];
    const [from, to, step] = parts.map(Number);
    const steps = (to - from) / step + 1e-9;
    if (![from, to, step].every(Number.isFinite) || !(step > 0) || to < from
        || !(steps < MAX_ANGLES)) return [t];
    const out = [];
    for (let i = 0; i <= Math.floor(steps); i++) {
      out.push(Math.min(Math.round((from + i * step) * 1e9) / 1e9, to) + 0);
    }
    return out;
  }
  return list(t).map((s) => (NUMBER.test(s) ? Number(s) : s));
}

function formBody(form, names) {
  const body = {};
  for (const name of names) {
    const v = value(form.elements[name].value);
    if (v !== undefined) body[name] = v;
  }
  return body;
}

// -- screens ------------------------------------------------------------------------------------
function showScreen(name) {
  $$(".screen").forEach((s) => { s.hidden = s.dataset.screen !== name; });
  $$(".tab").forEach((t) => t.classList.toggle("active", t.dataset.screen === name));
  if (name === "calibration") refreshCalibration();
  if (name === "campaigns") refreshCampaigns();
}

function screenFromHash() {
  const name = location.hash.replace("#", "");
  showScreen(["rig", "campaigns", "calibration"].includes(name) ? name : "rig");
}

// -- token ----------------------------------------------------------------------------------------
function showTokenState() {
  $("#token-state").textContent = token() ? "token kept for this session" : "read-only";
}

// -- rig ------------------------------------------------------------------------------------------
const FIXES = [
  [/Timeout|does not answer|no reply/i, "The device does not answer: check its cable and power."],
  [/LampFault|lamp/i, "Relight the lamp (Lamp On); replace it if it will not light."],
  [/following error|stall|disabled|DISABLE/i, "Enable the turntable controller (Enable)."],
  [/not referenced|home/i, "Reference the stage (Home)."],
  [/not configured|not available/i, "Start the service with the device's port or --simulated."],
];

function fixFor(text) {
  const hit = FIXES.find(([re]) => re.test(text));
  return hit ? hit[1] : "";
}

function fmt(v, digits = 2) {
  return typeof v === "number" ? v.toFixed(digits) : String(v);
}

function deviceCard(d) {
  const el = document.createElement("div");
  el.className = `device ${d.ok ? "ok" : "bad"}`;
  el.dataset.device = d.name;
  const rows = [];
  const x = d.details || {};
  if (d.name === "turntable" && d.ok) {
    rows.push(`position <b class="angle">${fmt(x.angle_deg)} deg</b>`,
              `limits ${fmt(x.limits_deg[0], 0)} to ${fmt(x.limits_deg[1], 0)} deg`);
  } else if (d.name === "solar_simulator" && d.ok) {
    rows.push(`lamp <b>${x.lamp_on ? "on" : "off"}</b>, level ${fmt(x.suns)} sun`,
              `shutter <b>${x.shutter_open ? "open" : "closed"}</b>`);
  } else if (d.name === "camera" && d.ok) {
    rows.push(`use case <b>${x.use_case}</b>`);
    const temp = x.temperature_c ?? x.temperature_degc ?? x.temperature;
    if (temp !== undefined) rows.push(`temperature ${fmt(temp, 1)} °C`);
    if (x.serial) rows.push(`serial ${x.serial}`);
  }
  if (x.status) rows.push(`<span class="hint">${x.status}</span>`);
  el.innerHTML = `<h3>${d.name.replace("_", " ")} <span class="dot"></span></h3>`
    + rows.map((r) => `<div>${r}</div>`).join("");
  if (!d.ok) {
    const err = document.createElement("div");
    err.className = "why";
    const fix = document.createElement("b");
    fix.className = "fix";
    fix.textContent = fixFor(d.error);
    const said = document.createElement("div");
    said.className = "hint";
    said.textContent = d.error;
    err.append(fix, said);
    el.appendChild(err);
  }
  return el;
}

async function refreshRig() {
  const res = await call("GET", `${API}/devices`);
  if (!res.ok) return;
  const box = $("#devices");
  box.replaceChildren(...res.data.devices.map(deviceCard));
  const holder = res.data.campaign_id ? `campaign ${res.data.campaign_id}`
    : res.data.calibration_id ? `calibration job ${res.data.calibration_id}` : "";
  $("#rig-holder").textContent = holder
    ? `The rig is held by ${holder}: manual commands wait until it ends.` : "";
}

async function post(path, body, form) {
  const res = await call("POST", path, body);
  if (form) showErrors(form, res);
  else if (!res.ok) say(problem(res), "error");
  refreshRig();
  return res;
}

async function emergencyStop() {
  const res = await call("POST", `${API}/devices/stop`);
  if (res.ok) {
    const d = res.data;
    const parts = [`Stopped: ${d.stopped.join(", ") || "nothing"}`];
    if (d.campaign_paused) parts.push(`campaign ${d.campaign_paused} paused`);
    if (d.calibration_cancelled) parts.push(`calibration ${d.calibration_cancelled} cancelled`);
    const errs = Object.entries(d.errors).map(([k, v]) => `${k}: ${v}`);
    say(parts.concat(errs).join("; "), errs.length ? "error" : "warn");
  } else {
    say(`Emergency stop: ${problem(res)}`, "error");
  }
  refreshRig();
}

// -- a pose -----------------------------------------------------------------------------------
async function runPose(event) {
  event.preventDefault();
  const form = event.target;
  const body = formBody(form, ["turntable_deg", "solar_suns", "spp"]);
  body.scene = form.elements.scene.value;
  $("#pose-status").textContent = "moving, capturing, simulating...";
  $("#pose-run").disabled = true;
  const res = await post(`${API}/poses`, body, form);
  $("#pose-run").disabled = false;
  $("#pose-status").textContent = res.ok ? "" : "not run";
  if (res.ok) await fragment(`/ui/poses/${res.data.id}`, $("#pose-result"));
}

// -- campaigns ---------------------------------------------------------------------------------
const followed = {id: null, source: null, done: -1, status: null};

async function createCampaign(event) {
  event.preventDefault();
  const form = event.target;
  const repeats = value(form.elements.repeats.value);
  const levels = list(form.elements.solar_suns.value).map(value);
  const poses = [];
  for (const a of angles(form.elements.angles.value)) {
    for (const s of levels.length ? levels : [undefined]) {
      const p = {turntable_deg: a};
      if (s !== undefined) p.solar_suns = s;
      if (repeats !== undefined) p.repeats = repeats;
      poses.push(p);
    }
  }
  const body = {name: form.elements.name.value, scene: form.elements.scene.value, poses};
  const spp = value(form.elements.spp.value);
  if (spp !== undefined) body.spp = spp;
  if (form.elements.object_fit.checked) body.object_fit = true;
  const res = await call("POST", `${API}/campaigns`, body);
  showErrors(form, res);
  if (res.ok) {
    say(`Campaign ${body.name} created: ${poses.length} poses. Start it when the rig is ready.`);
    follow(res.data.id);
    refreshCampaigns();
  }
}

function refreshCampaigns() {
  return fragment("/ui/campaigns", $("#campaign-list"));
}

function whyActions(status) {
  const box = $("#cc-why");
  box.replaceChildren();
  const err = status.error;
  const stuck = ["paused", "failed", "interrupted"].includes(status.state);
  box.hidden = !(stuck && err) && status.state !== "interrupted";
  if (box.hidden) return;
  const text = document.createElement("p");
  const what = {paused: "Paused", failed: "Failed", interrupted: "Interrupted"}[status.state];
  text.textContent = `${what}: ${err || "the service stopped while it ran"}.`;
  box.appendChild(text);
  const actions = [];
  if (/turntable|SMC|stage|following|stall/i.test(err || "")) {
    actions.push(["Enable the turntable", `${API}/devices/turntable/enable`, undefined]);
  }
  if (/lamp|solar|Oriel/i.test(err || "")) {
    actions.push(["Relight the lamp", `${API}/devices/solar/lamp`, {on: true}]);
  }
  const advice = document.createElement("p");
  advice.className = "hint";
  advice.textContent = /emergency stop/i.test(err || "")
    ? "Check the rig is safe, then resume."
    : /space|disk/i.test(err || "") ? "Free space on the data directory's disk, then resume."
      : "Fix the cause, then resume: the poses done are kept, the rest are measured.";
  box.appendChild(advice);
  for (const [label, path, body] of actions) {
    const b = document.createElement("button");
    b.type = "button";
    b.textContent = label;
    b.addEventListener("click", () => post(path, body));
    box.appendChild(b);
  }
  const resume = document.createElement("button");
  resume.type = "button";
  resume.textContent = "Resume";
  resume.className = "why-resume";
  resume.addEventListener("click", () => control("resume"));
  box.appendChild(resume);
}

function describePose(p) {
  if (!p) return "";
  if (p.stage === "object_fit") return `fitting the object twin: view ${p.pose_index + 1}`;
  return `pose ${p.pose_index + 1}: ${fmt(p.turntable_deg, 1)} deg, ${fmt(p.solar_suns)} sun`
    + (p.repeat ? `, repeat ${p.repeat + 1}` : "");
}

function renderCampaign(status) {
  followed.status = status;
  $("#campaign-current").hidden = false;
  $("#cc-live").hidden = false;
  $("#cc-name").textContent = status.name;
  const state = $("#cc-state");
  state.textContent = status.state;
  state.className = `state state-${status.state}`;
  $("#cc-progress").textContent = `${status.poses_done} / ${status.poses_total} poses`;
  const bar = $("#cc-bar");
  bar.max = Math.max(status.poses_total, 1);
  bar.value = status.poses_done;
  $("#cc-eta").textContent = status.eta_s != null && status.state === "running"
    ? `about ${Math.ceil(status.eta_s)} s left` : "";
  const when = {running: "now", paused: "next", interrupted: "next"}[status.state];
  $("#cc-pose").textContent = when && status.current_pose
    ? `${when}: ${describePose(status.current_pose)}` : "";
  const s = status.state;
  $("#cc-start").disabled = s !== "created";
  $("#cc-pause").disabled = s !== "running";
  $("#cc-resume").disabled = !["paused", "interrupted", "failed"].includes(s);
  $("#cc-cancel").disabled = CAMPAIGN_TERMINAL.includes(s);
  const l = status.links;
  $("#cc-links").innerHTML = `<a href="${l.report}" target="_blank">report</a> &middot; `
    + `<a href="${l.results}?format=csv">CSV</a> &middot; `
    + `<a href="${l.documents}" target="_blank">documents</a>`;
  whyActions(status);
  if (status.poses_done !== followed.done) {
    followed.done = status.poses_done;
    refreshLive(status);
  }
}

function plotNames(status) {
  const box = $("#cc-plots");
  const names = box.dataset.plots.split(" ");
  return status.object_fit ? names.concat(box.dataset.explainedPlots.split(" ")) : names;
}

async function refreshLive(status) {
  const id = status.id;
  const done = status.poses_done;
  const box = $("#cc-plots");
  box.replaceChildren(...plotNames(status).map((name) => {
    const img = document.createElement("img");
    img.className = "plot";
    img.alt = `${name} over the poses`;
    img.src = `${API}/campaigns/${id}/plots/${name}.svg?n=${done}`;
    return img;
  }));
  // Statuses arrive faster than a pose's images load: only the newest request may fill in.
  const seq = (refreshLive.seq = (refreshLive.seq || 0) + 1);
  const latest = () => seq === refreshLive.seq && followed.id === id;
  if (done > 0) {
    const res = await call("GET", `${API}/campaigns/${id}/results?offset=${done - 1}&limit=1`);
    if (res.ok && res.data.length && latest()) {
      const html = await call("GET", `/ui/poses/${res.data[0].id}`);
      if (html.ok && latest()) $("#cc-latest").innerHTML = html.data;
    }
  } else {
    $("#cc-latest").innerHTML = '<p class="hint">no pose yet</p>';
  }
  if (status.object_fit) await fragment(`/ui/campaigns/${id}/explained`, $("#cc-explained"));
  else $("#cc-explained").replaceChildren();
  refreshCampaigns();
}

async function follow(id) {
  if (followed.source) followed.source.close();
  Object.assign(followed, {id, source: null, done: -1, status: null});
  const res = await call("GET", `${API}/campaigns/${id}`);
  if (!res.ok) { say(problem(res), "error"); return; }
  renderCampaign(res.data);
  if (CAMPAIGN_TERMINAL.includes(res.data.state)) return;
  listen(id);
}

// A stream the service refused (too many open, or it restarted) is closed for good by the
// browser: open a new one a little later while the campaign is still the one followed.
function reopenOnError(source, reopen, isCurrent) {
  source.addEventListener("error", () => {
    if (source.readyState === EventSource.CLOSED && isCurrent()) {
      say("Live updates were interrupted; reconnecting.", "warn");
      setTimeout(() => { if (isCurrent()) reopen(); }, 3000);
    }
  });
}

function listen(id) {
  const source = new EventSource(`${API}/campaigns/${id}/events`);
  followed.source = source;
  reopenOnError(source, () => listen(id), () => followed.id === id && followed.source === source);
  source.addEventListener("status", (event) => {
    if (followed.id !== id) return;
    const status = JSON.parse(event.data);
    renderCampaign(status);
    if (CAMPAIGN_TERMINAL.includes(status.state)) {
      source.close();
      refreshRig();
    }
  });
}

async function control(action) {
  const id = followed.id;
  if (!id) return;
  const res = await call("POST", `${API}/campaigns/${id}/${action}`);
  if (!res.ok) { say(problem(res), "error"); return; }
  renderCampaign(res.data);
  if (!CAMPAIGN_TERMINAL.includes(res.data.state) && followed.source
      && followed.source.readyState === EventSource.CLOSED) listen(id);
  refreshRig();
}

async function followLatest() {
  const res = await call("GET", `${API}/campaigns?limit=5`);
  if (!res.ok) return;
  const open = res.data.find((c) => !CAMPAIGN_TERMINAL.includes(c.state) && c.state !== "created");
  if (open) follow(open.id);
}

// -- calibration -------------------------------------------------------------------------------
const calibration = {id: null, source: null};

async function refreshCalibration() {
  await fragment("/ui/calibration", $("#calibration-active"));
  $$("[data-epoch]").forEach((el) => {
    el.textContent = new Date(Number(el.dataset.epoch) * 1000).toLocaleString();
  });
}

function renderJob(job) {
  $("#calibration-job").hidden = false;
  $("#cj-state").textContent = job.state;
  const what = job.message && job.message !== job.state ? `${job.message} ` : "";
  $("#cj-message").textContent = `${what}(${job.steps_done} / ${job.steps_total} steps)`;
  $("#cj-bar").value = job.progress;
  const err = $("#cj-error");
  err.hidden = !job.error && !job.operator_instruction;
  err.textContent = job.error || job.operator_instruction || "";
  $("#cj-continue").hidden = !job.operator_instruction;
  $("#cj-cancel").disabled = CALIBRATION_TERMINAL.includes(job.state);
  $("#cj-links").innerHTML = job.state === "done"
    ? `<a href="${API}/calibrations/${job.id}/files/report.html" target="_blank">report</a>`
      + ` &middot; <a href="${API}/calibrations/${job.id}/files/calibration.yaml">calibration.yaml</a>`
      + ` &middot; <a href="${API}/calibrations/${job.id}/files/verdicts.json">verdicts.json</a>`
    : "";
  renderVerdicts(job);
}

// The done job's verdicts: the calibration report's table, rendered by the service
// (/ui/calibrations/{id}/verdicts, escaped there); loaded once per job.
function renderVerdicts(job) {
  const box = $("#cj-verdicts");
  if (job.state !== "done" || !job.verdicts) {
    box.hidden = true;
    box.replaceChildren();
    delete box.dataset.job;
    return;
  }
  if (box.dataset.job === job.id) return;
  box.dataset.job = job.id;
  fetch(`/ui/calibrations/${job.id}/verdicts`)
    .then((res) => (res.ok ? res.text() : ""))
    .then((html) => {
      if (box.dataset.job !== job.id) return;  // another job meanwhile
      box.innerHTML = html;
      box.hidden = html.trim() === "";
    });
}

function followJob(id) {
  if (calibration.source) calibration.source.close();
  calibration.id = id;
  const source = new EventSource(`${API}/calibrations/${id}/events`);
  calibration.source = source;
  reopenOnError(source, () => followJob(id),
                () => calibration.id === id && calibration.source === source);
  source.addEventListener("status", (event) => {
    const job = JSON.parse(event.data);
    renderJob(job);
    if (CALIBRATION_TERMINAL.includes(job.state)) {
      source.close();
      refreshCalibration();
      refreshRig();
    }
  });
}

async function startCalibration(event) {
  event.preventDefault();
  const form = event.target;
  const body = {
    fixtures: ["tilt+30@200mm", "tilt-30@200mm"],
    sweep: formBody(form, ["from_deg", "to_deg", "step_deg"]),
    ...formBody(form, ["frames_per_view", "noise_frames"]),
    warmup_stage: form.elements.warmup_stage.checked,
    settling_stage: form.elements.settling_stage.checked,
    activate: form.elements.activate.checked,
  };
  const res = await call("POST", `${API}/calibrations`, body);
  showErrors(form, res);
  if (res.ok) { renderJob(res.data); followJob(res.data.id); }
}

// The latest job: followed while it runs; once ended, shown as it ended (its verdicts too).
async function followRunningJob() {
  const res = await call("GET", `${API}/calibrations?limit=1`);
  if (!res.ok || !res.data.length) return;
  renderJob(res.data[0]);
  if (!CALIBRATION_TERMINAL.includes(res.data[0].state)) followJob(res.data[0].id);
}

// -- wiring ------------------------------------------------------------------------------------
function wire() {
  $$(".tab").forEach((t) => t.addEventListener("click", () => {
    history.replaceState(null, "", `#${t.dataset.screen}`);
    showScreen(t.dataset.screen);
  }));
  $("#estop").addEventListener("click", emergencyStop);
  $("#token").value = token();
  showTokenState();
  $("#token-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const t = $("#token").value.trim();
    if (t) sessionStorage.setItem(TOKEN_KEY, t); else sessionStorage.removeItem(TOKEN_KEY);
    showTokenState();
  });
  $$("[data-post]").forEach((b) => b.addEventListener("click", () => {
    const body = b.dataset.body ? JSON.parse(b.dataset.body) : undefined;
    post(b.dataset.post, body).then((res) => {
      if (res.ok && res.data.frame_id) {
        $("#capture-result").textContent = `frame ${res.data.frame_id}`;
      }
    });
  }));
  $("#move-form").addEventListener("submit", (event) => {
    event.preventDefault();
    post(`${API}/devices/turntable/move`, formBody(event.target, ["angle_deg"]), event.target);
  });
  $("#level-form").addEventListener("submit", (event) => {
    event.preventDefault();
    post(`${API}/devices/solar/level`, formBody(event.target, ["suns"]), event.target);
  });
  $("#pose-form").addEventListener("submit", runPose);
  $("#campaign-form").addEventListener("submit", createCampaign);
  $$("[data-action]").forEach((b) => b.addEventListener("click", () => control(b.dataset.action)));
  $("#campaign-list").addEventListener("click", (event) => {
    const id = event.target.dataset.follow;
    if (id) follow(id);
  });
  $("#calibration-form").addEventListener("submit", startCalibration);
  $("#cj-cancel").addEventListener("click", () => {
    if (calibration.id) post(`${API}/calibrations/${calibration.id}/cancel`);
  });
  $("#cj-continue").addEventListener("click", () => {
    if (calibration.id) post(`${API}/calibrations/${calibration.id}/continue`);
  });
  window.addEventListener("hashchange", screenFromHash);
  screenFromHash();
  refreshRig();
  setInterval(refreshRig, RIG_POLL_MS);
  refreshCampaigns();
  followLatest();
  followRunningJob();
}

document.addEventListener("DOMContentLoaded", wire);
