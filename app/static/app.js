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
let timer = null;

async function api(path, options = {}) {
  const resp = await fetch(path, options);
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
  timer = null;
}

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
}

const PLANE_ROLES = ["exemplar_xy", "exemplar_xz", "exemplar_yz"];

function previewFile(input, img) {
  const file = input.files[0];
  img.hidden = !file;
  if (file) img.src = URL.createObjectURL(file);
}

async function renderHome() {
  $("#view").replaceChildren($("#tpl-home").content.cloneNode(true));
  $("#exemplar").addEventListener("change", () => previewFile($("#exemplar"), $("#exemplar-preview")));
  $("#constraint").addEventListener("change", () => previewFile($("#constraint"), $("#constraint-preview")));
  for (const plane of PLANE_ROLES) {
    $(`#${plane}`).addEventListener("change", () => previewFile($(`#${plane}`), $(`#${plane}-preview`)));
  }
  $("#method").addEventListener("change", showMethod);
  $("#reset-params").addEventListener("click", showMethod);
  $("#job-form").addEventListener("submit", submitJob);
  try {
    methods = (await api("/api/methods")).data;
  } catch (err) {
    showError(err);
    return;
  }
  for (const m of methods) $("#method").append(el("option", { value: m.name, text: m.name }));
  const preferred = methods.find((m) => m.name === "wei-levoy");
  if (preferred) $("#method").value = preferred.name;
  showMethod();
  refreshJobs();
}

function showError(err) {
  const box = $("#form-error");
  if (!box) return;
  box.hidden = false;
  box.textContent = err.message;
  document.querySelectorAll(".invalid").forEach((n) => n.classList.remove("invalid"));
  const target = err.field && (document.getElementById(`param-${err.field}`) || document.getElementById(err.field));
  if (target) {
    target.classList.add("invalid");
    target.focus();
  }
}

async function submitJob(event) {
  event.preventDefault();
  $("#form-error").hidden = true;
  const button = $("#submit");
  button.disabled = true;
  const form = new FormData();
  for (const role of ["exemplar", "constraint", ...PLANE_ROLES]) {
    const input = $(`#${role}`);
    const box = $(`#${role}-box`);
    if (input.files[0] && !(box && box.hidden)) form.append(role, input.files[0]);
  }
  form.append("method", $("#method").value);
  form.append("params", JSON.stringify({ ...readFields($("#size-fields")), ...readFields($("#param-fields")) }));
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

async function refreshJobs() {
  const tbody = $("#jobs-table tbody");
  if (!tbody) return;
  try {
    const { data } = await api("/api/jobs?limit=20");
    tbody.replaceChildren(...data.map((j) => el("tr", {},
      el("td", {}, el("a", { href: `#/jobs/${j.id}`, text: j.id.slice(0, 8) })),
      el("td", { text: j.method }),
      el("td", { text: `${j.params.width ?? "?"}×${j.params.height ?? "?"}` }),
      el("td", {}, el("span", { class: `state ${j.state}`, text: j.state })),
      el("td", { text: j.state === "running" ? `${Math.round(100 * j.fraction)}%` : "" }),
      el("td", { text: fmtTime(j.created) }))));
  } catch (err) { /* the next refresh retries */ }
  timer = setTimeout(refreshJobs, 2000);
}

// -- the job page ----------------------------------------------------------------------------------

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

async function renderJob(id) {
  $("#view").replaceChildren($("#tpl-job").content.cloneNode(true));
  $("#job-id").textContent = id.slice(0, 8);
  $("#cancel").addEventListener("click", async () => {
    $("#cancel").disabled = true;
    try { await api(`/api/jobs/${id}`, { method: "DELETE" }); } catch (err) { alert(err.message); }
  });
  let shownInputs = false;
  const poll = async () => {
    let job;
    try {
      job = await api(`/api/jobs/${id}`);
    } catch (err) {
      $("#job-message").hidden = false;
      $("#job-message").textContent = err.message;
      if (err.status !== 404) timer = setTimeout(poll, 2000);
      return;
    }
    const sizeText = `${job.params.width}×${job.params.height}${job.params.depth ? "×" + job.params.depth : ""}`;
    $("#job-state").textContent = job.state + (job.cancel_requested && job.state === "running" ? " (cancelling)" : "");
    $("#job-state").className = `state ${job.state}`;
    $("#job-summary").textContent = `${job.method}, ${sizeText}, seed ${job.seed} — submitted ${fmtTime(job.created)}` +
      (job.elapsed ? `, ${job.elapsed.toFixed(1)} s` : "") + (job.attempts > 1 ? `, run ${job.attempts}` : "");
    $("#progress").value = job.state === "succeeded" ? 1 : job.fraction;
    $("#progress").classList.toggle("failed", job.state === "failed");
    $("#progress-text").textContent = job.state === "failed"
      ? `failed during ${job.stage || "the run"}`
      : `${Math.round(100 * (job.state === "succeeded" ? 1 : job.fraction))}% ${job.stage}`;
    $("#cancel").hidden = !["queued", "running"].includes(job.state);
    $("#job-message").hidden = !job.message;
    $("#job-message").textContent = job.message;
    $("#live").hidden = !job.preview;
    if (job.preview) $("#preview").src = job.preview;
    if (!shownInputs) {
      for (const [role, url] of Object.entries(job.inputs)) $("#inputs").append(figure(url, role));
      showParams(job);
      shownInputs = true;
    }
    if (job.state === "succeeded") showResults(job);
    if (["queued", "running"].includes(job.state)) timer = setTimeout(poll, 500);
  };
  poll();
}

// A volume's slices, one at a time: the plane (xy = fixed z, xz = fixed y, yz = fixed x) and a slider.
function showVolumeViewer(job) {
  const depth = job.params.depth;
  $("#volume-viewer").hidden = !depth;
  if (!depth) return;
  const count = { xy: depth, xz: job.params.height, yz: job.params.width };
  const axis = { xy: "z", xz: "y", yz: "x" };
  const slider = $("#slice-index");
  const show = () => {
    const plane = $("#slice-plane").value;
    const index = Math.min(parseInt(slider.value, 10), count[plane] - 1);
    $("#slice-label").textContent = `${axis[plane]} = ${index} of ${count[plane] - 1}`;
    $("#slice-image").src = `/api/jobs/${job.id}/slices/${plane}/${index}.png`;
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
  $("#job-params tbody").replaceChildren(...rows);
}

let glossary = null;
async function measures() {
  if (!glossary) {
    try { glossary = await api("/api/metrics"); } catch (err) { glossary = {}; }
  }
  return glossary;
}

// One row per headline measure: value, a verdict against the documented threshold, and its meaning.
async function showMetrics(summary) {
  const g = await measures();
  const rows = [];
  for (const [name, value] of Object.entries(summary || {})) {
    if (typeof value !== "number") continue;
    const m = g[name];
    let verdict = "";
    if (m && m.good_below !== null && m.good_below !== undefined) {
      verdict = Math.abs(value) < m.good_below ? `good (< ${m.good_below})` : `off (target < ${m.good_below})`;
    }
    const cls = verdict.startsWith("good") ? "verdict good" : verdict ? "verdict off" : "verdict";
    rows.push(el("tr", {}, el("th", { text: m ? m.label : name }), el("td", { text: fmtNum(value) }),
      el("td", {}, el("span", { class: cls, text: verdict })),
      el("td", { class: "hint", text: m ? `${m.meaning}; ${m.better} is better` : "" })));
  }
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

function showResults(job) {
  const a = job.artifacts;
  $("#results").hidden = false;
  showVolumeViewer(job);
  const captions = { "output.png": job.params.depth ? "output (middle xy slice)" : "output",
    "cube.png": "the volume: outer faces and a corner cut away", "slices.png": "mid-slices beside their exemplars",
    "coherence.png": "coherence (output)", "orientation.png": "orientation (output)",
    "constraint_coherence.png": "coherence (constraint)", "constraint_orientation.png": "orientation (constraint)" };
  const images = $("#result-images");
  images.replaceChildren();
  for (const [name, caption] of Object.entries(captions)) {
    if (a[name]) images.append(figure(a[name], caption, name === "output.png" ? "result" : undefined));
  }
  for (const name of Object.keys(a)) {
    if (name.endsWith(".png") && !captions[name] && !name.startsWith("plots/")) images.append(figure(a[name], name));
  }
  const metrics = Object.entries(flatten(job.metrics)).filter(([k]) => !k.startsWith("settings."));
  const row = ([k, v]) => el("tr", {}, el("th", { text: k }), el("td", { text: fmtNum(v) }));
  showMetrics((job.metrics && job.metrics.summary) || Object.fromEntries(metrics));
  $("#all-metrics tbody").replaceChildren(...metrics.map(row));
  $("#plots").replaceChildren(...Object.keys(a).filter((n) => n.startsWith("plots/"))
    .map((n) => figure(a[n], n.slice(6).replace(".png", "").replaceAll("_", " "))));
  $("#downloads").replaceChildren(...Object.entries(a).map(([n, url]) =>
    el("li", {}, el("a", { href: url, download: n.replace("plots/", ""), text: n }))));
}

// -- routing and health --------------------------------------------------------------------------

function route() {
  stopTimer();
  const m = location.hash.match(/^#\/jobs\/([0-9a-f]+)/);
  if (m) renderJob(m[1]);
  else renderHome();
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
window.addEventListener("DOMContentLoaded", () => { route(); health(); });
