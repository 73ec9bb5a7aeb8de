// texsynth browser page: plain JavaScript, no build step. Talks only to the REST API under /api.
"use strict";

const $ = (sel, root = document) => root.querySelector(sel);
const el = (tag, attrs = {}, ...children) => {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") node.textContent = v;
    else if (v !== undefined && v !== null && v !== false) node.setAttribute(k, v === true ? "" : v);
  }
  node.append(...children);
  return node;
};
const fmtTime = (t) => (t ? new Date(t * 1000).toLocaleString() : "");
const fmtNum = (v) => (typeof v === "number" ? (Number.isInteger(v) ? String(v) : v.toPrecision(4)) : String(v));

let methods = [];
let timer = null; // the current page's poller (one at a time)
let blinkTimer = null; // the compare page's blink
let relayout = null; // the current page's viewer layout, re-run when the window resizes
let generation = 0; // incremented on every route change: a stale page's async work stops

// -- the API token (when the service has tokens) ---------------------------------------------------
// Kept in sessionStorage (this tab's session only; tabs opened from the page inherit it), or in
// localStorage when "remember" is ticked. It is sent only as an Authorization header by fetch; it is
// never put in a URL. Images and download links use the per-job signed URLs the API gives instead.
const TOKEN_KEY = "texsynth-token";
let askingToken = null; // one prompt at a time, however many requests got a 401

const token = () => sessionStorage.getItem(TOKEN_KEY) || localStorage.getItem(TOKEN_KEY) || "";

function forgetToken() {
  sessionStorage.removeItem(TOKEN_KEY);
  localStorage.removeItem(TOKEN_KEY);
  showTokenState();
}

function showTokenState() {
  const button = $("#token-forget");
  if (button) button.hidden = !token();
}

function askToken(message) {
  if (askingToken) return askingToken;
  const dialog = $("#token-dialog");
  $("#token-message").textContent = message;
  $("#token-input").value = "";
  askingToken = new Promise((resolve) => {
    const form = $("#token-form");
    form.onsubmit = (event) => {
      event.preventDefault();
      const value = $("#token-input").value.trim();
      if (!value) return;
      forgetToken();
      ($("#token-remember").checked ? localStorage : sessionStorage).setItem(TOKEN_KEY, value);
      dialog.close();
      askingToken = null;
      showTokenState();
      resolve(value);
    };
  });
  dialog.oncancel = (event) => event.preventDefault(); // nothing works without it: Escape does not dismiss
  dialog.showModal();
  $("#token-input").focus();
  return askingToken;
}

// fetch with the token; a 401 asks for a (new) token and tries again
async function authFetch(path, options = {}) {
  for (;;) {
    const headers = new Headers(options.headers || {});
    if (token()) headers.set("Authorization", `Bearer ${token()}`);
    const resp = await fetch(path, { ...options, headers });
    if (resp.status !== 401) return resp;
    const body = await resp.clone().json().catch(() => ({}));
    await askToken(token() ? `That token was refused: ${body.detail || "HTTP 401"}` : "This service needs an API token.");
  }
}

// a download link of an API URL that needs the token (the sweep's CSV): fetched, then saved
function tokenDownload(event) {
  if (!token()) return; // no tokens: the plain link works
  event.preventDefault();
  const link = event.currentTarget;
  authFetch(link.href).then((resp) => resp.blob()).then((blob) => {
    const url = URL.createObjectURL(blob);
    const a = el("a", { href: url, download: link.getAttribute("download") || "" });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  });
}

const signed = (url, access) => (access ? `${url}${url.includes("?") ? "&" : "?"}access=${access}` : url);

async function api(path, options = {}) {
  const resp = await authFetch(path, options);
  const body = resp.headers.get("content-type")?.includes("json") ? await resp.json() : await resp.text();
  if (!resp.ok) {
    const err = new Error(typeof body === "object" ? body.detail : `HTTP ${resp.status}: ${body}`);
    err.field = body?.field;
    err.status = resp.status;
    throw err;
  }
  return body;
}

function stopTimer() {
  if (timer) clearTimeout(timer);
  if (blinkTimer) clearInterval(blinkTimer);
  timer = blinkTimer = relayout = null;
}

const radioValue = (name) => document.querySelector(`input[name="${name}"]:checked`)?.value;
const short = (id) => id.slice(0, 8);
// A job's output size (its own field, never inside its params).
const sizeOf = (job) => {
  const s = job.size || {};
  return `${s.width ?? "?"}×${s.height ?? "?"}${s.depth ? "×" + s.depth : ""}`;
};

// -- the parameter form, generated from the method's JSON schema (defaults = the papers' settings) --

function resolve(prop) {
  // {anyOf: [{enum|type}, {type: null}]} -> the non-null branch, nullable
  if (prop.anyOf) {
    const branch = prop.anyOf.find((b) => b.type !== "null") || {};
    return { ...prop, ...branch, nullable: prop.anyOf.some((b) => b.type === "null") };
  }
  return prop;
}

function fieldFor(name, raw, required) {
  const prop = resolve(raw);
  const title = prop.title || name;
  let input;
  if (prop.enum) {
    input = el("select", { name, "data-kind": "enum" });
    if (prop.nullable) input.append(el("option", { value: "", text: "(automatic)" }));
    for (const v of prop.enum) input.append(el("option", { value: v, text: v }));
    input.value = prop.default ?? "";
  } else if (prop.type === "boolean") {
    input = el("input", { type: "checkbox", name, "data-kind": "boolean" });
    input.checked = !!prop.default;
  } else if (prop.type === "integer" || prop.type === "number") {
    input = el("input", {
      type: "number", name, "data-kind": prop.type,
      min: prop.minimum ?? (prop.exclusiveMinimum !== undefined ? prop.exclusiveMinimum : undefined),
      max: prop.maximum ?? prop.exclusiveMaximum, step: prop.type === "integer" ? 1 : "any",
      placeholder: prop.nullable ? "automatic" : "", required: required && !prop.nullable,
    });
    input.value = prop.default ?? "";
  } else {
    input = el("input", { type: "text", name, "data-kind": "string", placeholder: prop.nullable ? "automatic" : "" });
    input.value = prop.default ?? "";
  }
  input.dataset.default = prop.type === "boolean" ? String(!!prop.default) : String(prop.default ?? "");
  input.id = `param-${name}`;
  return el("label", { title: prop.description || "" }, `${title} `, input,
    el("span", { class: "hint", text: prop.description || "" }));
}

function buildFields(container, schema) {
  container.replaceChildren();
  const required = new Set(schema.required || []);
  for (const [name, prop] of Object.entries(schema.properties || {})) container.append(fieldFor(name, prop, required.has(name)));
}

function readFields(container) {
  const out = {};
  for (const input of container.querySelectorAll("[name]")) {
    const kind = input.dataset.kind;
    if (kind === "boolean") out[input.name] = input.checked;
    else if (input.value === "") continue; // nullable: let the engine choose
    else if (kind === "integer") out[input.name] = parseInt(input.value, 10);
    else if (kind === "number") out[input.name] = parseFloat(input.value);
    else out[input.name] = input.value;
  }
  return out;
}

function showMethod() {
  const m = methods.find((x) => x.name === $("#method").value);
  if (!m) return;
  $("#method-summary").textContent = `${m.summary}${m.paper ? " — " + m.paper : ""}`;
  buildFields($("#size-fields"), m.size_schema);
  buildFields($("#param-fields"), m.params_schema);
  // The method declares its inputs (role -> required | optional | alternative): ask for exactly those.
  const inputs = m.inputs || { exemplar: "required" };
  $("#constraint-box").hidden = !inputs.constraint;
  $("#constraint-need").textContent = inputs.constraint === "required" ? "(required)" : "(optional)";
  $("#constraint").required = inputs.constraint === "required";
  $("#exemplar").required = inputs.exemplar === "required";
  for (const plane of PLANE_ROLES) $(`#${plane}-box`).hidden = !inputs[plane];
  $("#inputs-hint").hidden = !PLANE_ROLES.some((plane) => inputs[plane]);
  sweepChoices();
}

const PLANE_ROLES = ["exemplar_xy", "exemplar_xz", "exemplar_yz"];

function previewFile(input, img) {
  const file = input.files[0];
  img.hidden = !file;
  if (file) img.src = URL.createObjectURL(file);
}

async function renderHome(fromJob) {
  const gen = generation;
  $("#view").replaceChildren($("#tpl-home").content.cloneNode(true));
  $("#exemplar").addEventListener("change", () => previewFile($("#exemplar"), $("#exemplar-preview")));
  $("#constraint").addEventListener("change", () => previewFile($("#constraint"), $("#constraint-preview")));
  for (const plane of PLANE_ROLES) {
    $(`#${plane}`).addEventListener("change", () => previewFile($(`#${plane}`), $(`#${plane}-preview`)));
  }
  $("#method").addEventListener("change", showMethod);
  $("#reset-params").addEventListener("click", showMethod);
  $("#job-form").addEventListener("submit", submitJob);
  $("#sweep-param").addEventListener("change", () => sweepSuggest());
  for (const input of document.querySelectorAll("#sweep-box input")) input.addEventListener("input", sweepPreview);
  $("#sweep-submit").addEventListener("click", submitSweep);
  try {
    methods = (await api("/api/methods")).data;
  } catch (err) {
    showError(err);
    return;
  }
  if (gen !== generation) return;
  for (const m of methods) $("#method").append(el("option", { value: m.name, text: m.name }));
  const preferred = methods.find((m) => m.name === "wei-levoy");
  if (preferred) $("#method").value = preferred.name;
  showMethod();
  if (fromJob) await fillFromJob(fromJob);
  refreshJobs(gen);
}

function showError(err, target) {
  const box = $("#form-error");
  if (!box) return;
  box.hidden = false;
  box.textContent = err.message;
  document.querySelectorAll(".invalid").forEach((n) => n.classList.remove("invalid"));
  target = target || (err.field && (document.getElementById(`param-${err.field}`) || document.getElementById(err.field)));
  if (target) {
    target.classList.add("invalid");
    target.focus();
  }
}

// The multipart body shared by a job and a sweep: the chosen inputs, the method, its parameters and
// the output size (form fields width, height, depth).
function formBody(params, size) {
  const form = new FormData();
  for (const role of ["exemplar", "constraint", ...PLANE_ROLES]) {
    const input = $(`#${role}`);
    const box = $(`#${role}-box`);
    if (input.files[0] && !(box && box.hidden)) form.append(role, input.files[0]);
  }
  form.append("method", $("#method").value);
  form.append("params", JSON.stringify(params));
  for (const [name, value] of Object.entries(size)) form.append(name, String(value));
  return form;
}

const formParams = () => readFields($("#param-fields"));
const formSize = () => readFields($("#size-fields"));

async function submitJob(event) {
  event.preventDefault();
  $("#form-error").hidden = true;
  const button = $("#submit");
  button.disabled = true;
  const form = formBody(formParams(), formSize());
  if ($("#seed").value !== "") form.append("seed", $("#seed").value);
  try {
    const job = await api("/api/jobs", { method: "POST", body: form });
    location.hash = `#/jobs/${job.id}`;
  } catch (err) {
    showError(err);
  } finally {
    button.disabled = false;
  }
}

// "Run again with these settings": the job's method, size, seed and parameters, and its stored inputs
// fetched back from the service and put into the file fields (so nothing needs re-choosing).
async function fillFromJob(id) {
  const note = $("#rerun-note");
  let job;
  try {
    job = await api(`/api/jobs/${id}`);
  } catch (err) {
    showError(err);
    return;
  }
  if (!$("#job-form")) return; // the page was left meanwhile
  if (!methods.some((m) => m.name === job.method)) {
    showError(new Error(`job ${short(id)} used the method '${job.method}', which this service no longer offers`));
    return;
  }
  $("#method").value = job.method;
  showMethod();
  for (const [name, value] of Object.entries({ ...job.size, ...job.params })) {
    const input = document.getElementById(`param-${name}`);
    if (!input) continue;
    if (input.dataset.kind === "boolean") input.checked = !!value;
    else input.value = value ?? "";
  }
  $("#seed").value = job.seed;
  const reused = [];
  const missing = [];
  for (const [role, url] of Object.entries(job.inputs)) {
    const input = document.getElementById(role);
    try {
      const resp = await authFetch(url);
      if (!resp.ok) throw new Error(`HTTP ${resp.status}`);
      const blob = await resp.blob();
      if (!input.isConnected) return;
      const ext = { "image/png": "png", "image/tiff": "tiff", "image/jpeg": "jpg" }[blob.type] || "png";
      const files = new DataTransfer();
      files.items.add(new File([blob], `${role}-${short(id)}.${ext}`, { type: blob.type }));
      input.files = files.files;
      input.dispatchEvent(new Event("change"));
      reused.push(role.replace("_", " "));
    } catch (err) {
      missing.push(role.replace("_", " "));
    }
  }
  note.hidden = false;
  note.textContent = `The settings of job ${short(id)} are filled in (method, size, seed ${job.seed}, parameters)` +
    (reused.length ? `; its ${reused.join(", ")} reused` : "") +
    (missing.length ? `; choose the ${missing.join(", ")} again (the browser could not fetch them)` : "") +
    ". Change anything, then submit.";
}

// -- the sweep form: one parameter over a list or a range of values, times a list of seeds -----------

function sweepChoices() {
  const select = $("#sweep-param");
  if (!select) return;
  const inputs = [...document.querySelectorAll("#size-fields [name], #param-fields [name]")];
  select.replaceChildren(...inputs.map((input) => el("option", { value: input.name, text: input.name })));
  const preferred = inputs.find((i) => i.closest("#param-fields") && ["integer", "number"].includes(i.dataset.kind));
  if (preferred) select.value = preferred.name;
  sweepSuggest();
}

// A starting list for the chosen parameter: its enum, or values around its current one.
function sweepSuggest() {
  const input = document.getElementById(`param-${$("#sweep-param").value}`);
  if (!input) return;
  const kind = input.dataset.kind;
  const numeric = kind === "integer" || kind === "number";
  $("#sweep-kind").querySelector("input[value=range]").disabled = !numeric;
  if (!numeric) $("#sweep-kind").querySelector("input[value=list]").checked = true;
  let values = [];
  if (kind === "enum") values = [...input.options].map((o) => o.value).filter((v) => v !== "");
  else if (kind === "boolean") values = ["false", "true"];
  else if (numeric && input.value !== "") {
    const v = Number(input.value);
    values = kind === "integer" ? [Math.max(Number(input.min || 1), Math.round(v / 2)), v, v * 2] : [v / 2, v, v * 2];
  }
  $("#sweep-values").value = [...new Set(values)].join(", ");
  if (numeric && input.value !== "") {
    $("#sweep-from").value = values[0];
    $("#sweep-to").value = values[values.length - 1];
  }
  sweepPreview();
}

function fieldError(message, field) {
  const err = new Error(message);
  err.target = field;
  return err;
}

// The sweep's values (typed like the parameter's field) and seeds, or an error naming the field.
function sweepPlan() {
  const name = $("#sweep-param").value;
  const input = document.getElementById(`param-${name}`);
  if (!input) throw fieldError("choose a parameter to sweep", $("#sweep-param"));
  const kind = input.dataset.kind;
  let values;
  const range = radioValue("sweep-kind") === "range";
  $("#sweep-list-fields").hidden = range;
  $("#sweep-range-fields").hidden = !range;
  if (range) {
    const from = Number($("#sweep-from").value);
    const to = Number($("#sweep-to").value);
    const count = parseInt($("#sweep-count").value, 10);
    if ($("#sweep-from").value === "" || !Number.isFinite(from)) throw fieldError("give the first value", $("#sweep-from"));
    if ($("#sweep-to").value === "" || !Number.isFinite(to)) throw fieldError("give the last value", $("#sweep-to"));
    if (!(count >= 2 && count <= 50)) throw fieldError("the number of values must lie in [2, 50]", $("#sweep-count"));
    values = Array.from({ length: count }, (_, i) => from + (i * (to - from)) / (count - 1));
    values = values.map((v) => (kind === "integer" ? Math.round(v) : Number(v.toPrecision(6))));
  } else {
    const words = $("#sweep-values").value.split(/[,;\s]+/).filter(Boolean);
    if (!words.length) throw fieldError("give at least one value, separated by commas", $("#sweep-values"));
    values = words.map((w) => {
      if (kind === "integer" && /^[-+]?\d+$/.test(w)) return parseInt(w, 10);
      if (kind === "number" && w !== "" && Number.isFinite(Number(w))) return Number(w);
      if (kind === "boolean" && /^(true|false)$/i.test(w)) return w.toLowerCase() === "true";
      if (kind === "enum" || kind === "string") return w;
      throw fieldError(`'${w}' is not a valid ${kind} for ${name}`, $("#sweep-values"));
    });
  }
  values = [...new Set(values)];
  const seedWords = $("#sweep-seeds").value.split(/[,;\s]+/).filter(Boolean);
  const seeds = seedWords.length ? seedWords.map((w) => {
    if (!/^\d+$/.test(w)) throw fieldError(`seed '${w}' must be a whole number ≥ 0`, $("#sweep-seeds"));
    return parseInt(w, 10);
  }) : [0];
  return { name, values, seeds: [...new Set(seeds)] };
}

function sweepPreview() {
  const out = $("#sweep-preview");
  try {
    const { name, values, seeds } = sweepPlan();
    out.textContent = `${values.length * seeds.length} runs: ${name} = ${values.join(", ")}; ` +
      `seed${seeds.length > 1 ? "s" : ""} ${seeds.join(", ")}`;
    out.classList.remove("bad");
  } catch (err) {
    out.textContent = err.message;
    out.classList.add("bad");
  }
}

// One sweep per seed (the API runs a grid with one seed); the sweep page shows them together.
async function submitSweep() {
  $("#form-error").hidden = true;
  let plan;
  try {
    plan = sweepPlan();
  } catch (err) {
    showError(err, err.target);
    return;
  }
  const button = $("#sweep-submit");
  button.disabled = true;
  const params = formParams();
  const size = formSize();
  delete params[plan.name];
  delete size[plan.name];
  const ids = [];
  try {
    for (const seed of plan.seeds) {
      const form = formBody(params, size);
      form.append("grid", JSON.stringify({ [plan.name]: plan.values }));
      form.append("seed", String(seed));
      ids.push((await api("/api/sweeps", { method: "POST", body: form })).id);
    }
    location.hash = `#/sweeps/${ids.join(",")}`;
  } catch (err) {
    const grid = err.field && err.field.startsWith("grid");
    showError(err, grid ? $("#sweep-values") : undefined);
    if (ids.length) location.hash = `#/sweeps/${ids.join(",")}`;
  } finally {
    button.disabled = false;
  }
}

async function refreshJobs(gen = generation) {
  const tbody = $("#jobs-table tbody");
  if (!tbody || gen !== generation) return;
  try {
    const { data } = await api("/api/jobs?limit=20");
    tbody.replaceChildren(...data.map((j) => el("tr", {},
      el("td", {}, el("a", { href: `#/jobs/${j.id}`, text: short(j.id) }),
        j.sweep_id ? el("a", { href: `#/sweeps/${j.sweep_id}`, class: "hint sweep-tag", text: " sweep" }) : ""),
      el("td", { text: j.method }),
      el("td", { text: sizeOf(j) }),
      el("td", {}, el("span", { class: `state ${j.state}`, text: j.state })),
      j.state === "failed"
        ? el("td", { class: "reason", title: j.message, text: j.message })
        : el("td", { text: j.state === "running" ? `${Math.round(100 * j.fraction)}%` : "" }),
      el("td", { text: fmtTime(j.created) }))));
  } catch (err) { /* the next refresh retries */ }
  if (gen === generation) timer = setTimeout(() => refreshJobs(gen), 2000);
}

// -- the job page ----------------------------------------------------------------------------------

async function renderJob(id) {
  const gen = generation;
  $("#view").replaceChildren($("#tpl-job").content.cloneNode(true));
  $("#job-id").textContent = short(id);
  $("#cancel").addEventListener("click", async () => {
    $("#cancel").disabled = true;
    try { await api(`/api/jobs/${id}`, { method: "DELETE" }); } catch (err) { alert(err.message); }
  });
  $("#rerun").addEventListener("click", () => { location.hash = `#/new?from=${id}`; });
  let shownInputs = false;
  const poll = async () => {
    let job;
    try {
      job = await api(`/api/jobs/${id}`);
    } catch (err) {
      if (gen !== generation) return;
      $("#job-message").hidden = false;
      $("#job-message").textContent = err.message;
      if (err.status !== 404) timer = setTimeout(poll, 2000);
      return;
    }
    if (gen !== generation) return;
    $("#job-state").textContent = job.state + (job.cancel_requested && job.state === "running" ? " (cancelling)" : "");
    $("#job-state").className = `state ${job.state}`;
    $("#job-summary").textContent = `${job.method}, ${sizeOf(job)}, seed ${job.seed} — submitted ${fmtTime(job.created)}` +
      (job.elapsed ? `, ${job.elapsed.toFixed(1)} s` : "") + (job.attempts > 1 ? `, run ${job.attempts}` : "");
    $("#progress").value = job.state === "succeeded" ? 1 : job.fraction;
    $("#progress").classList.toggle("failed", job.state === "failed");
    const stage = ["failed", "cancelled"].includes(job.stage) ? "" : job.stage;
    $("#progress-text").textContent = job.state === "failed"
      ? `failed at ${Math.round(100 * job.fraction)}%${stage ? ` during ${stage}` : ""}: the reason is below`
      : `${Math.round(100 * (job.state === "succeeded" ? 1 : job.fraction))}% ${job.stage}`;
    $("#cancel").hidden = !["queued", "running"].includes(job.state);
    $("#job-message").hidden = !job.message;
    $("#job-message").textContent = job.message;
    $("#live").hidden = !job.preview;
    if (job.preview) $("#preview").src = job.preview;
    if (!shownInputs) {
      for (const [role, url] of Object.entries(job.inputs)) $("#inputs").append(figure(url, role));
      if (job.sweep_id) {
        $("#sweep-link").append("one run of a ", el("a", { href: `#/sweeps/${job.sweep_id}`, text: "sweep" }));
      }
      showParams(job);
      shownInputs = true;
    }
    showTimings(job);
    if (job.state === "succeeded") showResults(job);
    if (["queued", "running"].includes(job.state)) timer = setTimeout(poll, 500);
  };
  poll();
}

// Where the time went: waiting in the queue, the method's own stages (its Result.timings), and the
// evaluation and artifact writing that follow the synthesis.
function showTimings(job) {
  if (!job.started || !job.finished) return;
  const run = job.finished - job.started;
  const stages = Object.entries(job.timings || {}).filter(([k]) => k !== "total");
  const total = job.timings && job.timings.total;
  const rows = [[job.attempts > 1 ? `waiting (queue and ${job.attempts - 1} lost run(s))` : "waiting in the queue",
    job.started - job.created, 0]];
  rows.push([job.state === "succeeded" ? "run (start to artifacts committed)" : `run (until ${job.state})`, run, 0]);
  if (total !== undefined) {
    rows.push(["in the engine (synthesize)", total, 1]);
    for (const [name, seconds] of stages) rows.push([name.replaceAll("_", " "), seconds, 2]);
    rows.push(["evaluation, plots and artifacts", Math.max(0, run - total), 1]);
  }
  const longest = Math.max(...rows.map((r) => r[1]), 1e-9);
  $("#timings tbody").replaceChildren(...rows.map(([name, seconds, depth]) => {
    const bar = el("span", { class: "bar" });
    bar.style.width = `${(100 * Math.max(0, seconds)) / longest}%`;
    return el("tr", {}, el("th", { class: `depth-${depth}`, text: name }),
      el("td", { class: "num", text: seconds < 10 ? seconds.toFixed(2) : seconds.toFixed(1) }),
      el("td", { class: "bar-cell" }, bar));
  }));
  $("#timings-box").hidden = false;
}

// -- the viewer: exemplar and output at one pixel scale, zoom, tiling, tensor images ---------------

// The scale for a zoom choice: a number, or "fit" (the largest that fits the box; whole when >= 1, so
// every pixel stays a square of the same size).
function zoomScale(choice, width, height, boxWidth, boxHeight) {
  if (choice !== "fit") return Number(choice);
  const s = Math.min(boxWidth / Math.max(width, 1), boxHeight / Math.max(height, 1), 8);
  return s >= 1 ? Math.floor(s) : s;
}

function setSize(node, width, height) {
  node.style.width = `${Math.round(width)}px`;
  if (height !== undefined) node.style.height = `${Math.round(height)}px`;
}

function showViewer(job) {
  const a = job.artifacts;
  const W = job.size.width;
  const H = job.size.height;
  const exemplar = $("#view-exemplar");
  exemplar.src = job.inputs.exemplar || job.inputs.exemplar_xy;
  $("#result").src = a["output.png"];
  // three more copies of the output for the 2x2 tiling (decorative: the first one carries the alt)
  const tiles = $("#tiles");
  for (let i = 0; i < 3; i++) tiles.append(el("img", { src: a["output.png"], alt: "", class: "tile-copy", hidden: true }));
  for (const kind of ["coherence", "orientation"]) {
    $(`#fig-${kind}`).hidden = !a[`${kind}.png`];
    if (a[`${kind}.png`]) $(`#view-${kind}`).src = a[`${kind}.png`];
  }
  const layout = () => {
    if (!tiles.isConnected) return; // an image loaded after the page was left
    const tiled = $("#tile").checked;
    tiles.classList.toggle("tiled", tiled);
    tiles.querySelectorAll(".tile-copy").forEach((img) => { img.hidden = !tiled; });
    const exW = exemplar.naturalWidth || 0;
    const exH = exemplar.naturalHeight || 0;
    const outW = tiled ? 2 * W : W;
    const outH = tiled ? 2 * H : H;
    const box = $("#stage").clientWidth - 60;
    const scale = zoomScale(radioValue("zoom"), exW + outW, Math.max(exH, outH), box, 0.6 * window.innerHeight);
    setSize(exemplar, exW * scale, exH * scale);
    tiles.querySelectorAll("img").forEach((img) => setSize(img, W * scale, H * scale));
    // The tensor images carry their legend below (and are padded to its width): show only the
    // output-sized part, at the output's scale; the page draws a compact legend instead.
    for (const kind of ["coherence", "orientation"]) {
      const img = $(`#view-${kind}`);
      setSize(img.parentElement, W * scale, H * scale);
      if (img.naturalWidth) setSize(img, img.naturalWidth * scale, img.naturalHeight * scale);
    }
    const px = (n) => Math.round(n * scale);
    $("#cap-exemplar").textContent = `exemplar ${exW}×${exH}`;
    $("#cap-output").textContent = `output ${W}×${H}${tiled ? ", tiled 2×2: look for seams along the middle lines" : ""}`;
    const label = { fit: "fit", 1: "1:1", 2: "2x", 4: "4x" }[radioValue("zoom")];
    $("#zoom-status").textContent = `zoom ${label}: one pixel = ${Number(scale.toFixed(2))} screen pixels; ` +
      `output shown at ${px(W)}×${px(H)}`;
  };
  document.querySelectorAll("input[name=zoom]").forEach((r) => r.addEventListener("change", layout));
  $("#tile").addEventListener("change", layout);
  for (const img of $("#viewer").querySelectorAll("img")) img.addEventListener("load", layout);
  relayout = layout;
  layout();
}

// Other finished jobs to compare with (newest first).
async function compareChoices(job) {
  const select = $("#compare-with");
  const go = $("#compare-go");
  try {
    const { data } = await api("/api/jobs?state=succeeded&limit=100");
    for (const j of data) {
      if (j.id !== job.id) select.append(el("option", { value: j.id, text: jobLabel(j) }));
    }
  } catch (err) { /* the chooser stays empty */ }
  go.addEventListener("click", () => {
    if (select.value) location.hash = `#/compare/${job.id}/${select.value}`;
    else select.focus();
  });
}

const jobLabel = (j) => `${short(j.id)} · ${j.method} ${sizeOf(j)} seed ${j.seed}`;

function figure(src, caption, id) {
  return el("figure", {}, el("a", { href: src, target: "_blank" }, el("img", { src, alt: caption, id })),
    el("figcaption", { text: caption }));
}

function flatten(obj, prefix = "", out = {}) {
  for (const [k, v] of Object.entries(obj || {})) {
    if (v && typeof v === "object" && !Array.isArray(v)) flatten(v, `${prefix}${k}.`, out);
    else if (typeof v === "number" || typeof v === "boolean") out[`${prefix}${k}`] = v;
  }
  return out;
}

// A volume's slices, one at a time: the plane (xy = fixed z, xz = fixed y, yz = fixed x) and a slider.
function showVolumeViewer(job) {
  const depth = job.size.depth;
  $("#volume-viewer").hidden = !depth;
  if (!depth) return;
  const count = { xy: depth, xz: job.size.height, yz: job.size.width };
  const axis = { xy: "z", xz: "y", yz: "x" };
  const slider = $("#slice-index");
  const show = () => {
    const plane = $("#slice-plane").value;
    const index = Math.min(parseInt(slider.value, 10), count[plane] - 1);
    $("#slice-label").textContent = `${axis[plane]} = ${index} of ${count[plane] - 1}`;
    $("#slice-image").src = signed(`/api/jobs/${job.id}/slices/${plane}/${index}.png`, job.access);
    $("#slice-caption").textContent = `${plane} slice at ${axis[plane]} = ${index}`;
  };
  const reset = () => {
    const plane = $("#slice-plane").value;
    slider.max = count[plane] - 1;
    slider.value = Math.floor(count[plane] / 2);
    show();
  };
  $("#slice-plane").onchange = reset;
  slider.oninput = show;
  reset();
}

// The parameters the job ran with, the method's defaults marked (from its schema).
async function showParams(job) {
  let schema = {};
  try {
    const m = (await api("/api/methods")).data.find((x) => x.name === job.method);
    schema = (m && m.params_schema.properties) || {};
  } catch (err) { /* the table still lists the values */ }
  const rows = Object.entries(job.params).map(([name, value]) => {
    const known = schema[name];
    const isDefault = known && JSON.stringify(known.default) === JSON.stringify(value);
    return el("tr", {}, el("th", { text: name, title: (known && known.description) || "" }),
      el("td", { text: typeof value === "object" ? JSON.stringify(value) : String(value) }),
      el("td", { class: "hint", text: known ? (isDefault ? "default" : `default ${JSON.stringify(known.default)}`) : "" }));
  });
  if ($("#job-params")) $("#job-params tbody").replaceChildren(...rows);
}

let glossary = null;
async function measures() {
  if (!glossary) {
    try { glossary = await api("/api/metrics"); } catch (err) { glossary = {}; }
  }
  return glossary;
}

// A value against its measure's documented threshold: "good", "off", or "" (no threshold).
function verdictOf(m, value) {
  if (!m || m.good_below === null || m.good_below === undefined || typeof value !== "number") return "";
  return Math.abs(value) < m.good_below ? "good" : "off";
}

// One row per headline measure: value, a verdict against the documented threshold, and its meaning.
async function showMetrics(summary) {
  const g = await measures();
  const rows = [];
  for (const [name, value] of Object.entries(summary || {})) {
    if (typeof value !== "number") continue;
    const m = g[name];
    const v = verdictOf(m, value);
    const verdict = v === "good" ? `good (< ${m.good_below})` : v === "off" ? `off (target < ${m.good_below})` : "";
    const cls = `verdict ${v}`;
    rows.push(el("tr", {}, el("th", { text: m ? m.label : name }), el("td", { text: fmtNum(value) }),
      el("td", {}, el("span", { class: cls, text: verdict })),
      el("td", { class: "hint", text: m ? `${m.meaning}; ${m.better} is better` : "" })));
  }
  if (!$("#metrics")) return; // the page was left while the glossary loaded
  $("#metrics tbody").replaceChildren(...rows);
  // A volume: the same measures per axis (the slices normal to z, y and x: the xy, xz and yz planes).
  const perAxis = summary && summary.per_axis;
  $("#axis-metrics").hidden = !perAxis;
  if (!perAxis) return;
  const axes = [["0", "xy slices"], ["1", "xz slices"], ["2", "yz slices"]].filter(([a]) => perAxis[a]);
  $("#axis-metrics thead").replaceChildren(el("tr", {}, el("th", { text: "measure" }),
    ...axes.map(([, label]) => el("th", { text: label }))));
  const names = Object.keys(perAxis[axes[0][0]]).filter((n) => typeof perAxis[axes[0][0]][n] === "number");
  $("#axis-metrics tbody").replaceChildren(...names.map((name) => {
    const m = g[name];
    return el("tr", {}, el("th", { text: m ? m.label : name, title: m ? m.meaning : "" }),
      ...axes.map(([a]) => {
        const v = perAxis[a][name];
        const off = m && m.good_below != null && typeof v === "number" && Math.abs(v) >= m.good_below;
        return el("td", { class: off ? "verdict off" : "", text: fmtNum(v) });
      }));
  }));
}

// The exemplar's fringe statistics beside the output's, so a number is read against the sample's own.
const FRINGE_STATS = [["count", "fringes"], ["mean_length", "mean length (px)"], ["median_length", "median length (px)"],
  ["mean_tortuosity", "mean tortuosity"], ["share_tortuous", "share tortuous"], ["density_per_10k_px", "per 10k px"]];
function showFringes(fringes) {
  const ok = fringes && fringes.exemplar && fringes.output;
  $("#fringe-metrics").hidden = !ok;
  if (!ok) return;
  $("#fringe-metrics tbody").replaceChildren(...FRINGE_STATS.filter(([k]) => k in fringes.exemplar).map(([k, label]) =>
    el("tr", {}, el("th", { text: label }), el("td", { text: fmtNum(fringes.exemplar[k]) }),
      el("td", { text: fmtNum(fringes.output[k]) }))));
}

// The exemplar's diagnostics (metrics.exemplar): a plain warning when an exemplar mixes textures.
function showExemplarWarning(metrics) {
  const warnings = (metrics && metrics.exemplar && metrics.exemplar.warnings) || [];
  const box = $("#exemplar-warning");
  if (!box) return;
  box.hidden = warnings.length === 0;
  // "exemplar: The exemplar is not ..." reads as one sentence without its role; per-plane roles stay
  box.replaceChildren(...warnings.map((w) => el("span", { text: w.replace(/^exemplar: /, "") })));
}

function showResults(job) {
  const a = job.artifacts;
  const volume = !!job.size.depth;
  $("#results").hidden = false;
  showExemplarWarning(job.metrics);
  showVolumeViewer(job);
  // A 2-D output, its exemplar and its tensor images go to the viewer; a volume keeps its pictures.
  $("#viewer").hidden = volume || !a["output.png"];
  if (!$("#viewer").hidden) showViewer(job);
  const inViewer = volume ? new Set() : new Set(["output.png", "coherence.png", "orientation.png"]);
  const captions = { "output.png": volume ? "output (middle xy slice)" : "output",
    "cube.png": "the volume: outer faces and a corner cut away", "slices.png": "mid-slices beside their exemplars",
    "coherence.png": "coherence (output)", "orientation.png": "orientation (output)",
    "constraint_coherence.png": "coherence (constraint)", "constraint_orientation.png": "orientation (constraint)" };
  const images = $("#result-images");
  images.replaceChildren();
  for (const [name, caption] of Object.entries(captions)) {
    if (a[name] && !inViewer.has(name)) images.append(figure(a[name], caption, name === "output.png" ? "result" : undefined));
  }
  for (const name of Object.keys(a)) {
    if (name.endsWith(".png") && !captions[name] && !name.startsWith("plots/")) images.append(figure(a[name], name.replace(".png", "").replaceAll("_", " ")));
  }
  compareChoices(job);
  const metrics = Object.entries(flatten(job.metrics)).filter(([k]) => !k.startsWith("settings."));
  const row = ([k, v]) => el("tr", {}, el("th", { text: k }), el("td", { text: fmtNum(v) }));
  showMetrics((job.metrics && job.metrics.summary) || Object.fromEntries(metrics));
  showFringes(job.metrics && job.metrics.fringes);
  $("#all-metrics tbody").replaceChildren(...metrics.map(row));
  $("#plots").replaceChildren(...Object.keys(a).filter((n) => n.startsWith("plots/"))
    .map((n) => figure(a[n], n.slice(6).replace(".png", "").replaceAll("_", " "))));
  $("#downloads").replaceChildren(...Object.entries(a).map(([n, url]) =>
    el("li", {}, el("a", { href: url, download: n.replace("plots/", ""), text: n }))));
}

// -- comparing two jobs: swipe or blink between their outputs, their metrics side by side ---------

async function renderCompare(idA, idB) {
  const gen = generation;
  $("#view").replaceChildren($("#tpl-compare").content.cloneNode(true));
  let A, B, list;
  try {
    [A, B, list] = await Promise.all([api(`/api/jobs/${idA}`), api(`/api/jobs/${idB}`),
      api("/api/jobs?state=succeeded&limit=100"), measures()]);
  } catch (err) {
    $("#compare-error").hidden = false;
    $("#compare-error").textContent = err.message;
    return;
  }
  if (gen !== generation) return;
  const jobs = [A, B, ...list.data.filter((j) => j.id !== A.id && j.id !== B.id)];
  for (const [select, chosen, other] of [[$("#compare-a"), A, B], [$("#compare-b"), B, A]]) {
    select.replaceChildren(...jobs.map((j) => el("option", { value: j.id, text: jobLabel(j) })));
    select.value = chosen.id;
    select.addEventListener("change", () => {
      const ids = select.id === "compare-a" ? [select.value, other.id] : [other.id, select.value];
      location.hash = `#/compare/${ids[0]}/${ids[1]}`;
    });
  }
  const missing = [A, B].filter((j) => !j.artifacts["output.png"]);
  if (missing.length) {
    $("#compare-error").hidden = false;
    $("#compare-error").textContent = `job ${missing.map((j) => short(j.id)).join(" and ")} has no output ` +
      `(${missing.map((j) => j.state).join(", ")}); choose a finished job`;
  }
  const imgA = $("#compare-img-a");
  const imgB = $("#compare-img-b");
  imgA.src = A.artifacts["output.png"] || "";
  imgB.src = B.artifacts["output.png"] || "";
  imgA.alt = `output of job A (${jobLabel(A)})`;
  imgB.alt = `output of job B (${jobLabel(B)})`;
  const stack = $("#compare-stack");

  const showBlink = (showB) => {
    imgB.classList.toggle("hidden-layer", !showB);
    $("#blink-label").textContent = showB ? `B: ${jobLabel(B)}` : `A: ${jobLabel(A)}`;
  };
  let showingB = false;
  // paused by the person (the button), or from the start when the system asks for reduced motion
  let paused = window.matchMedia("(prefers-reduced-motion: reduce)").matches;
  const startBlink = () => {
    if (blinkTimer) clearInterval(blinkTimer);
    blinkTimer = setInterval(() => { showingB = !showingB; showBlink(showingB); }, 700);
    $("#blink-play").textContent = "pause";
    $("#blink-play").setAttribute("aria-pressed", "true");
  };
  const stopBlink = () => {
    if (blinkTimer) clearInterval(blinkTimer);
    blinkTimer = null;
    $("#blink-play").textContent = "play";
    $("#blink-play").setAttribute("aria-pressed", "false");
  };
  $("#blink-play").addEventListener("click", () => {
    paused = !!blinkTimer;
    if (paused) stopBlink();
    else startBlink();
  });

  const layout = () => {
    if (!stack.isConnected) return; // an image loaded after the page was left
    const mode = radioValue("compare-mode");
    const w = Math.max(imgA.naturalWidth, imgB.naturalWidth, 1);
    const h = Math.max(imgA.naturalHeight, imgB.naturalHeight, 1);
    const scale = zoomScale(radioValue("compare-zoom"), w, h, stack.parentElement.clientWidth - 30, 0.6 * window.innerHeight);
    setSize(stack, w * scale, h * scale);
    setSize(imgA, imgA.naturalWidth * scale, imgA.naturalHeight * scale);
    setSize(imgB, imgB.naturalWidth * scale, imgB.naturalHeight * scale);
    $("#swipe-box").hidden = mode !== "swipe";
    $("#blink-box").hidden = mode !== "blink";
    stack.classList.toggle("blinking", mode === "blink");
    if (mode === "swipe") {
      stopBlink();
      imgB.classList.remove("hidden-layer");
      const cut = (Number($("#swipe").value) / 100) * w * scale;
      imgB.style.clipPath = `inset(0 0 0 ${Math.round(cut)}px)`;
      $(".divider", stack).style.left = `${Math.round(cut)}px`;
    } else {
      imgB.style.clipPath = "none";
      if (paused) stopBlink();
      else if (!blinkTimer) startBlink();
      showBlink(showingB);
    }
  };
  stack.append(el("span", { class: "divider", "aria-hidden": "true" }));
  document.querySelectorAll("input[name=compare-mode], input[name=compare-zoom]").forEach((r) => r.addEventListener("change", layout));
  $("#swipe").addEventListener("input", layout);
  imgA.addEventListener("load", layout);
  imgB.addEventListener("load", layout);
  relayout = layout;
  layout();
  compareMetrics(A, B);
  compareSettings(A, B);
}

// Which value is better by the measure's direction; "" when equal or unknown.
function better(m, a, b) {
  if (typeof a !== "number" || typeof b !== "number" || a === b) return "";
  const dir = m ? m.better : "lower";
  const score = (v) => (dir === "higher" ? -v : dir === "closer to 1" ? Math.abs(v - 1) : Math.abs(v));
  return score(a) < score(b) ? "A" : score(b) < score(a) ? "B" : "";
}

async function compareMetrics(A, B) {
  const g = await measures();
  const sa = (A.metrics && A.metrics.summary) || {};
  const sb = (B.metrics && B.metrics.summary) || {};
  const names = [...new Set([...Object.keys(sa), ...Object.keys(sb)])]
    .filter((n) => typeof sa[n] === "number" || typeof sb[n] === "number");
  if (!$("#compare-metrics")) return;
  const cell = (m, v) => el("td", { class: `verdict ${verdictOf(m, v)}`, text: v === undefined ? "—" : fmtNum(v),
    title: verdictOf(m, v) ? `${verdictOf(m, v)} against the target < ${m.good_below}` : "" });
  $("#compare-metrics tbody").replaceChildren(...names.map((name) => {
    const m = g[name];
    const who = better(m, sa[name], sb[name]);
    return el("tr", {}, el("th", { text: m ? m.label : name, title: m ? `${m.meaning}; ${m.better} is better` : "" }),
      cell(m, sa[name]), cell(m, sb[name]),
      el("td", { text: who ? `${who} (${m ? m.better : "lower"} is better)` : "same" }));
  }));
}

function compareSettings(A, B) {
  const rows = [["method", A.method, B.method], ["size", sizeOf(A), sizeOf(B)], ["seed", A.seed, B.seed]];
  const names = [...new Set([...Object.keys(A.params), ...Object.keys(B.params)])]
    .filter((n) => !["width", "height", "depth"].includes(n));
  for (const n of names) rows.push([n, A.params[n], B.params[n]]);
  const text = (v) => (v === undefined ? "—" : typeof v === "object" ? JSON.stringify(v) : String(v));
  $("#compare-params tbody").replaceChildren(...rows.map(([name, a, b]) => {
    const differs = text(a) !== text(b);
    return el("tr", { class: differs ? "differs" : "" }, el("th", { text: name }), el("td", { text: text(a) }),
      el("td", {}, text(b), differs ? el("span", { class: "visually-hidden", text: " (differs)" }) : ""));
  }));
}

// -- a sweep's page: its runs in a live table, a plot of one measure against the swept parameter ---

async function renderSweep(ids) {
  const gen = generation;
  $("#view").replaceChildren($("#tpl-sweep").content.cloneNode(true));
  const seeds = {}; // sweep id -> the seed its runs share
  const g = await measures();
  if (gen !== generation) return;
  $("#sweep-metric").addEventListener("change", () => draw());
  let sweeps = [];
  const draw = () => drawSweep(sweeps, seeds, g);
  const poll = async () => {
    try {
      sweeps = await Promise.all(ids.map((id) => api(`/api/sweeps/${id}`)));
      for (const sweep of sweeps) {
        if (seeds[sweep.id] === undefined && sweep.rows.length) seeds[sweep.id] = (await api(`/api/jobs/${sweep.rows[0].job}`)).seed;
      }
    } catch (err) {
      if (gen !== generation) return;
      $("#sweep-error").hidden = false;
      $("#sweep-error").textContent = err.message;
      if (err.status !== 404) timer = setTimeout(poll, 2000);
      return;
    }
    if (gen !== generation) return;
    $("#sweep-error").hidden = true;
    draw();
    if (sweeps.some((s) => s.state === "running")) timer = setTimeout(poll, 1000);
  };
  await poll();
}

function csvLink(sweep, text) {
  const a = el("a", { href: `${sweep.url}?format=csv`, download: `sweep-${short(sweep.id)}.csv`, class: "csv", text });
  a.addEventListener("click", tokenDownload);
  return a;
}

function drawSweep(sweeps, seeds, g) {
  const first = sweeps[0];
  const params = Object.keys(first.grid);
  const param = params[0];
  const rows = sweeps.flatMap((s) => s.rows.map((r) => ({ ...r, seed: seeds[s.id] })));
  const counts = {};
  for (const r of rows) counts[r.state] = (counts[r.state] || 0) + 1;
  const ended = (counts.succeeded || 0) + (counts.failed || 0) + (counts.cancelled || 0);
  const running = sweeps.some((s) => s.state === "running");
  $("#sweep-name").textContent = params.join(", ");
  $("#sweep-state").textContent = running ? "running" : "done";
  $("#sweep-state").className = `state ${running ? "running" : "succeeded"}`;
  $("#sweep-summary").textContent = `${first.method}, ${sizeOf(first)}; ${param} = ${first.grid[param].join(", ")}; ` +
    `seed${sweeps.length > 1 ? "s" : ""} ${sweeps.map((s) => seeds[s.id] ?? "?").join(", ")}; ` +
    Object.entries(counts).map(([k, v]) => `${v} ${k}`).join(", ");
  $("#sweep-progress").value = rows.length ? ended / rows.length : 0;
  $("#sweep-progress-text").textContent = `${ended} of ${rows.length} runs ended`;
  $("#sweep-csv").replaceChildren("CSV: ", ...sweeps.flatMap((s, i) => [i ? " · " : "",
    csvLink(s, sweeps.length > 1 ? `seed ${seeds[s.id] ?? "?"}` : "download the table")]));

  // the headline measures (summary.*) that any run has, in the glossary's order
  const columns = [...new Set(sweeps.flatMap((s) => s.columns))];
  const metricCols = columns.filter((c) => /^summary\.[^.]+$/.test(c));
  metricCols.sort((a, b) => Object.keys(g).indexOf(a.slice(8)) - Object.keys(g).indexOf(b.slice(8)));
  const select = $("#sweep-metric");
  const chosen = select.value || (metricCols.includes("summary.grey_kl") ? "summary.grey_kl" : metricCols[0]);
  if (select.options.length !== metricCols.length) {
    select.replaceChildren(...metricCols.map((c) => el("option", { value: c, text: g[c.slice(8)]?.label || c.slice(8) })));
  }
  if (chosen) select.value = chosen;

  const label = (c) => g[c.slice(8)]?.label || c.slice(8);
  $("#sweep-table thead").replaceChildren(el("tr", {}, el("th", { text: "output" }), el("th", { text: "seed" }),
    ...params.map((p) => el("th", { text: p })), el("th", { text: "state" }),
    ...metricCols.map((c) => el("th", { text: label(c), title: g[c.slice(8)]?.meaning || "", class: c === chosen ? "chosen" : "" }))));
  $("#sweep-table tbody").replaceChildren(...rows.map((r) => {
    const name = `${params.map((p) => `${p} = ${r[p]}`).join(", ")}, seed ${r.seed}`;
    const thumb = r.state === "succeeded"
      ? el("a", { href: `#/jobs/${r.job}` }, el("img", { class: "thumb", src: signed(`/api/jobs/${r.job}/artifacts/output.png`, r.access), alt: `output of ${name}` }))
      : el("a", { href: `#/jobs/${r.job}`, text: short(r.job) });
    return el("tr", {}, el("td", {}, thumb), el("td", { text: r.seed ?? "" }),
      ...params.map((p) => el("td", { text: String(r[p]) })),
      el("td", {}, el("a", { href: `#/jobs/${r.job}`, class: `state ${r.state}`, text: r.state })),
      ...metricCols.map((c) => {
        const m = g[c.slice(8)];
        return el("td", { class: `num verdict ${verdictOf(m, r[c])}`, text: r[c] === undefined ? "" : fmtNum(r[c]) });
      }));
  }));

  // the plot: one series per seed
  const m = chosen ? g[chosen.slice(8)] : null;
  const series = sweeps.map((s) => ({
    name: `seed ${seeds[s.id] ?? "?"}`,
    points: s.rows.filter((r) => typeof r[chosen] === "number").map((r) => ({ x: r[param], y: r[chosen] })),
  }));
  const yLabel = chosen ? label(chosen) : "";
  const chart = plot(series, { xLabel: param, yLabel, threshold: m ? m.good_below : null });
  $("#sweep-plot").replaceChildren(chart);
  const target = m && m.good_below != null ? (chart.dataset.target === "shown"
    ? `; dashed line: the documented target < ${m.good_below}`
    : `; the documented target < ${m.good_below} lies far above every value`) : "";
  $("#sweep-plot-caption").textContent = chosen
    ? `${yLabel} against ${param}${m ? ` (${m.better} is better)` : ""}${target}` +
      (series.length > 1 ? "; one line per seed" : "")
    : "no run has finished yet";
}

// -- a small SVG line plot (no library): x numeric or categorical, y linear with round ticks -------

const SVG = "http://www.w3.org/2000/svg";
function svg(tag, attrs = {}, ...children) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") node.textContent = v;
    else node.setAttribute(k, v);
  }
  node.append(...children);
  return node;
}

function niceTicks(lo, hi, count = 5) {
  if (!(hi > lo)) {
    const pad = Math.abs(lo) * 0.1 || 1;
    lo -= pad;
    hi += pad;
  }
  const raw = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = mag * [1, 2, 5, 10].find((f) => f * mag >= raw);
  const start = Math.floor(lo / step) * step;
  const end = Math.ceil(hi / step) * step;
  const ticks = [];
  for (let v = start; v <= end + step / 2; v += step) ticks.push(Number(v.toPrecision(12)));
  return { lo: start, hi: end, ticks };
}

const PALETTE = ["#2357c6", "#c4320a", "#067647", "#7a2e9e", "#b54708", "#0e7090"];

function plot(series, { xLabel, yLabel, threshold }) {
  const W = 640;
  const H = 300;
  const M = { left: 84, right: 110, top: 16, bottom: 46 };
  const tick = (v) => String(Number(v.toPrecision(4)));
  const points = series.flatMap((s) => s.points);
  const root = svg("svg", { "data-target": "hidden", viewBox: `0 0 ${W} ${H}`, role: "img", "aria-labelledby": "plot-title plot-desc", id: "sweep-svg" });
  root.append(svg("title", { id: "plot-title", text: `${yLabel} against ${xLabel}` }));
  root.append(svg("desc", { id: "plot-desc", text: series.map((s) =>
    `${s.name}: ${s.points.map((p) => `${xLabel} ${p.x} gives ${fmtNum(p.y)}`).join("; ") || "no values yet"}`).join(". ") }));
  if (!points.length) {
    root.append(svg("text", { x: W / 2, y: H / 2, "text-anchor": "middle", class: "muted", text: "waiting for the first finished run…" }));
    return root;
  }
  // x: numbers on a linear axis, anything else (enum, booleans) as evenly spaced categories
  const numeric = points.every((p) => typeof p.x === "number");
  const categories = [...new Set(points.map((p) => String(p.x)))];
  const xs = numeric ? niceTicks(Math.min(...points.map((p) => p.x)), Math.max(...points.map((p) => p.x)), 6) : null;
  const xOf = numeric
    ? (x) => M.left + ((x - xs.lo) / (xs.hi - xs.lo)) * (W - M.left - M.right)
    : (x) => M.left + ((categories.indexOf(String(x)) + 0.5) / categories.length) * (W - M.left - M.right);
  let yMin = Math.min(0, ...points.map((p) => p.y));
  let yMax = Math.max(...points.map((p) => p.y));
  const showTarget = typeof threshold === "number" && threshold <= 3 * Math.max(yMax, 1e-12);
  if (showTarget) yMax = Math.max(yMax, threshold);
  const ys = niceTicks(yMin, yMax, 5);
  yMin = ys.lo;
  yMax = ys.hi;
  const yOf = (y) => H - M.bottom - ((y - yMin) / (yMax - yMin)) * (H - M.top - M.bottom);
  const axes = svg("g", { class: "axes" });
  for (const t of ys.ticks) {
    axes.append(svg("line", { x1: M.left, x2: W - M.right, y1: yOf(t), y2: yOf(t), class: "grid" }),
      svg("text", { x: M.left - 6, y: yOf(t) + 4, "text-anchor": "end", text: tick(t) }));
  }
  const xTicks = numeric ? xs.ticks : categories;
  for (const t of xTicks) {
    axes.append(svg("line", { x1: xOf(t), x2: xOf(t), y1: H - M.bottom, y2: H - M.bottom + 5, class: "tick" }),
      svg("text", { x: xOf(t), y: H - M.bottom + 18, "text-anchor": "middle", text: numeric ? tick(t) : t }));
  }
  axes.append(svg("line", { x1: M.left, x2: W - M.right, y1: H - M.bottom, y2: H - M.bottom, class: "axis" }),
    svg("line", { x1: M.left, x2: M.left, y1: M.top, y2: H - M.bottom, class: "axis" }),
    svg("text", { x: (M.left + W - M.right) / 2, y: H - 8, "text-anchor": "middle", class: "label", text: xLabel }),
    svg("text", { x: 14, y: (M.top + H - M.bottom) / 2, "text-anchor": "middle", class: "label",
      transform: `rotate(-90 14 ${(M.top + H - M.bottom) / 2})`, text: yLabel }));
  root.append(axes);
  if (showTarget) {
    root.dataset.target = "shown";
    root.append(svg("line", { x1: M.left, x2: W - M.right, y1: yOf(threshold), y2: yOf(threshold), class: "target" }),
      svg("text", { x: W - M.right + 4, y: yOf(threshold) + 4, class: "target-label", text: `target < ${threshold}` }));
  }
  series.forEach((s, i) => {
    const colour = PALETTE[i % PALETTE.length];
    const pts = [...s.points].sort((a, b) => (numeric ? a.x - b.x : categories.indexOf(String(a.x)) - categories.indexOf(String(b.x))));
    const group = svg("g", { class: "series", "data-series": s.name });
    if (pts.length > 1) {
      group.append(svg("polyline", { points: pts.map((p) => `${xOf(p.x)},${yOf(p.y)}`).join(" "), fill: "none", stroke: colour, "stroke-width": 2 }));
    }
    for (const p of pts) {
      group.append(svg("circle", { cx: xOf(p.x), cy: yOf(p.y), r: 4.5, fill: colour, class: "point" },
        svg("title", { text: `${xLabel} = ${p.x}, ${s.name}: ${yLabel} = ${fmtNum(p.y)}` })));
    }
    root.append(group);
    if (series.length > 1) {
      root.append(svg("circle", { cx: W - M.right + 12, cy: M.top + 8 + 18 * i, r: 4.5, fill: colour }),
        svg("text", { x: W - M.right + 22, y: M.top + 12 + 18 * i, text: s.name }));
    }
  });
  return root;
}

// -- routing and health --------------------------------------------------------------------------

function route() {
  stopTimer();
  generation += 1;
  const hash = location.hash;
  let m;
  if ((m = hash.match(/^#\/jobs\/([0-9a-f]+)/))) renderJob(m[1]);
  else if ((m = hash.match(/^#\/compare\/([0-9a-f]+)\/([0-9a-f]+)/))) renderCompare(m[1], m[2]);
  else if ((m = hash.match(/^#\/sweeps\/([0-9a-f,]+)/))) renderSweep(m[1].split(",").filter(Boolean));
  else renderHome((hash.match(/^#\/new\?from=([0-9a-f]+)/) || [])[1]);
}

async function health() {
  try {
    const resp = await fetch("/api/health");
    const body = await resp.json();
    $("#health").className = resp.ok ? "ok" : "bad";
    $("#health").title = body.message;
  } catch (err) {
    $("#health").className = "bad";
  }
  setTimeout(health, 10000);
}

window.addEventListener("hashchange", route);
window.addEventListener("resize", () => relayout && relayout());
window.addEventListener("DOMContentLoaded", () => {
  $("#token-forget").addEventListener("click", () => { forgetToken(); route(); });
  showTokenState();
  route();
  health();
});
