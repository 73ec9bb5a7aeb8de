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
    // {detail: "one line", field} or FastAPI's {detail: [{loc: [..., FIELD], msg}]}
    const detail = typeof body === "object" ? body.detail : `HTTP ${resp.status}: ${body}`;
    const errors = Array.isArray(detail)
      ? detail.map((d) => ({ field: String((d.loc || []).at(-1) ?? ""), where: (d.loc || [])[0], msg: String(d.msg || "") }))
      : body?.field ? [{ field: body.field, msg: String(detail).replace(/^parameter 'params' = \{.*\}: (Value error, )?/s, "") }] : [];
    const message = Array.isArray(detail)
      ? detail.map((d) => { const f = String((d.loc || []).at(-1) ?? ""); return d.msg.includes(f) ? d.msg : `${f}: ${d.msg}`; }).join("; ")
      : typeof detail === "string" ? detail.replace(/^parameter 'params' = \{.*\}: (Value error, )?/s, "") : JSON.stringify(detail);
    const err = new Error(message);
    err.field = errors[0]?.field;
    err.errors = errors;
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
// The schema marks the parameters a user changes ("x-basic"): those, the output size and the seed come
// first; the rest wait under "Advanced". Each field's help sits outside its label, tied to the input by
// aria-describedby (with its range, unit and "odd"), and its constraints are checked before submitting.

function resolve(prop) {
  // {anyOf: [{enum|type}, {type: null}]} or {type: [T, "null"]} -> the non-null branch, nullable
  if (Array.isArray(prop.type)) {
    return { ...prop, type: prop.type.find((t) => t !== "null"), nullable: prop.nullable || prop.type.includes("null") };
  }
  if (prop.anyOf) {
    const branch = prop.anyOf.find((b) => b.type !== "null") || {};
    return { ...prop, ...branch, nullable: prop.anyOf.some((b) => b.type === "null") };
  }
  return prop;
}

// "whole number, 3–15, odd": what the schema allows, in words
function rangeText(prop) {
  const parts = [];
  const lo = prop.minimum !== undefined ? `≥ ${prop.minimum}` : prop.exclusiveMinimum !== undefined ? `> ${prop.exclusiveMinimum}` : "";
  const hi = prop.maximum !== undefined ? `≤ ${prop.maximum}` : prop.exclusiveMaximum !== undefined ? `< ${prop.exclusiveMaximum}` : "";
  if (prop.minimum !== undefined && prop.maximum !== undefined) parts.push(`${prop.minimum}–${prop.maximum}`);
  else if (lo && hi) parts.push(`${lo} and ${hi}`);
  else if (lo || hi) parts.push(lo || hi);
  if (prop["x-odd"]) parts.push("odd");
  if (prop.type === "integer") parts.unshift("whole number");
  if (prop.nullable && !/empty:/.test(prop.description || "")) parts.push("empty: automatic");
  return parts.join(", ");
}

const unitOf = (prop) => prop["x-unit"] || "";

function fieldFor(name, raw, required) {
  const prop = resolve(raw);
  const title = prop.title || name;
  const id = `param-${name}`;
  const help = `${id}-help`;
  const error = `${id}-error`;
  const described = `${help} ${error}`;
  let input;
  let kind;
  const items = prop.type === "array" ? resolve(prop.items || {}) : null;
  if (items && items.enum) {
    // a list of names from a fixed set: one checkbox per name, sent as a JSON array
    kind = "array";
    const chosen = new Set(prop.default || []);
    input = el("div", { role: "group", id, "aria-labelledby": `${id}-label`, "aria-describedby": described, class: "choices", tabindex: "-1" },
      ...items.enum.map((v) => el("label", { class: "check" },
        el("input", { type: "checkbox", value: v, checked: chosen.has(v), "data-item": name }), ` ${v}`)));
  } else if (items) {
    kind = "list"; // free list: comma-separated text, sent as a JSON array
    input = el("input", { type: "text", id, "aria-describedby": described, placeholder: "comma-separated" });
    input.value = (prop.default || []).join(", ");
  } else if (prop.enum) {
    kind = "enum";
    input = el("select", { id, "aria-describedby": described });
    if (prop.nullable) input.append(el("option", { value: "", text: "(automatic)" }));
    for (const v of prop.enum) input.append(el("option", { value: v, text: v }));
    input.value = prop.default ?? "";
  } else if (prop.type === "boolean") {
    kind = "boolean";
    input = el("input", { type: "checkbox", id, "aria-describedby": described });
    input.checked = !!prop.default;
  } else if (prop.type === "integer" || prop.type === "number") {
    kind = prop.type;
    input = el("input", {
      type: "number", id, "aria-describedby": described, inputmode: prop.type === "integer" ? "numeric" : "decimal",
      min: prop.minimum ?? prop.exclusiveMinimum, max: prop.maximum ?? prop.exclusiveMaximum,
      step: prop.type === "integer" ? (prop["x-odd"] ? 2 : 1) : "any",
      placeholder: prop.nullable && !/empty:/.test(prop.description || "") ? "automatic" : "",
    });
    input.value = prop.default ?? "";
  } else {
    kind = "string";
    input = el("input", { type: "text", id, "aria-describedby": described, placeholder: prop.nullable ? "automatic" : "" });
    input.value = prop.default ?? "";
  }
  if (kind !== "array") input.setAttribute("name", name);
  input.dataset.kind = kind;
  input.dataset.default = JSON.stringify(prop.default ?? null);
  const unit = unitOf(prop);
  const label = kind === "array"
    ? el("span", { id: `${id}-label`, class: "label" }, title, unit ? el("span", { class: "unit", text: ` (${unit})` }) : "")
    : el("label", { for: id, id: `${id}-label` }, title, unit ? el("span", { class: "unit", text: ` (${unit})` }) : "");
  const range = rangeText(prop);
  const helpText = [prop.description || "", range ? `${range[0].toUpperCase()}${range.slice(1)}.` : ""].filter(Boolean).join(" ");
  const field = el("div", { class: `field kind-${kind}`, "data-name": name, "data-kind": kind },
    kind === "boolean" ? el("span", { class: "check-row" }, input, label) : label,
    kind === "boolean" ? "" : input,
    el("span", { class: "hint help", id: help, text: helpText }),
    el("span", { class: "field-error", id: error, hidden: true }));
  field.schema = { ...prop, required: required && !prop.nullable, items };
  field.input = input;
  return field;
}

// Which parameters are basic: the schema's "x-basic" marks; a schema without any (an older service)
// shows every parameter when there are few, otherwise the usual suspects.
const FALLBACK_BASIC = new Set(["neighbourhood_size", "patch_size", "periodic", "levels", "overlap", "metric", "planes",
  "structure", "iterations", "lambda_", "weight", "voxel_size"]);
function isBasic(schema, name) {
  const props = schema.properties || {};
  if (Object.values(props).some((p) => "x-basic" in p)) return !!props[name]["x-basic"];
  return Object.keys(props).length <= 8 || FALLBACK_BASIC.has(name);
}

function buildFields(schema, basic, advanced) {
  const required = new Set(schema.required || []);
  const props = schema.properties || {};
  // a field's unit chosen in another field ("x-unit-field": voxel_size's voxel_unit) sits beside it
  const unitFields = new Set(Object.values(props).map((p) => p["x-unit-field"]).filter(Boolean));
  for (const [name, prop] of Object.entries(props)) {
    if (unitFields.has(name)) continue;
    const field = fieldFor(name, prop, required.has(name));
    const unitName = prop["x-unit-field"];
    if (unitName && props[unitName]) {
      const unit = resolve(props[unitName]);
      const select = el("select", { id: `param-${unitName}`, name: unitName, class: "unit-select",
        "aria-label": unit.title || unitName, "aria-describedby": `param-${unitName}-help` },
      ...(unit.enum || []).map((v) => el("option", { value: v, text: v })));
      select.value = unit.default ?? "";
      const row = el("span", { class: "input-row" });
      field.input.replaceWith(row);
      row.append(field.input, select);
      field.append(el("span", { class: "visually-hidden", id: `param-${unitName}-help`, text: unit.description || "" }));
      field.unitInput = select;
      field.dataset.unitName = unitName;
    }
    (advanced && !isBasic(schema, name) ? advanced : basic).append(field);
  }
}

const formFields = (root) => [...root.querySelectorAll(".field[data-kind]")];

// The value a field holds, typed as its schema says; undefined = leave it to the engine (empty, nullable).
function fieldValue(field) {
  const kind = field.dataset.kind;
  const input = field.input;
  if (kind === "array") return [...field.querySelectorAll("input[data-item]:checked")].map((c) => c.value);
  if (kind === "boolean") return input.checked;
  const text = input.value.trim();
  if (kind === "list") {
    const type = field.schema.items?.type;
    return text.split(/[,;\s]+/).filter(Boolean).map((w) => (type === "integer" || type === "number" ? Number(w) : w));
  }
  if (text === "") return undefined;
  if (kind === "integer" || kind === "number") return Number(text);
  return input.value;
}

function setFieldValue(name, value) {
  const unitOwner = document.querySelector(`.field[data-unit-name="${name}"]`);
  if (unitOwner) {
    if (value) unitOwner.unitInput.value = value;
    return true;
  }
  const field = document.querySelector(`.field[data-name="${name}"]`);
  if (!field) return false;
  const input = field.input;
  const kind = field.dataset.kind;
  if (kind === "array") {
    const chosen = new Set(Array.isArray(value) ? value : [value]);
    field.querySelectorAll("input[data-item]").forEach((c) => { c.checked = chosen.has(c.value); });
  } else if (kind === "boolean") input.checked = value === true || value === "true";
  else if (kind === "list") input.value = (Array.isArray(value) ? value : [value]).join(", ");
  else input.value = value ?? "";
  clearFieldError(field);
  return true;
}

function readFields(container) {
  const out = {};
  for (const field of formFields(container)) {
    const value = fieldValue(field);
    if (value !== undefined) out[field.dataset.name] = value;
    if (field.unitInput && value !== undefined) out[field.dataset.unitName] = field.unitInput.value;
  }
  return out;
}

// The field's constraints, checked in the browser: "" when fine, else one line saying what to change.
function checkField(field) {
  const s = field.schema || {};
  const kind = field.dataset.kind;
  const title = (s.title || field.dataset.name).toLowerCase();
  const input = field.input;
  if (kind === "array") {
    const chosen = fieldValue(field);
    const least = s.minItems ?? 1;
    return chosen.length < least ? `${s.title || field.dataset.name}: choose at least ${least}` : "";
  }
  if (kind !== "integer" && kind !== "number") return "";
  const text = input.value.trim();
  if (text === "") return s.required || !s.nullable ? `${s.title || field.dataset.name}: give a value` : "";
  const v = Number(text);
  const unit = unitOf(s) ? ` ${unitOf(s)}` : "";
  if (!Number.isFinite(v)) return `${s.title || title}: '${text}' is not a number`;
  if (kind === "integer" && !Number.isInteger(v)) return `${s.title || title} must be a whole number (got ${text})`;
  if (s.minimum !== undefined && v < s.minimum) return `${s.title || title} must be at least ${s.minimum}${unit} (got ${text})`;
  if (s.maximum !== undefined && v > s.maximum) return `${s.title || title} must be at most ${s.maximum}${unit} (got ${text})`;
  if (s.exclusiveMinimum !== undefined && v <= s.exclusiveMinimum) return `${s.title || title} must be more than ${s.exclusiveMinimum}${unit} (got ${text})`;
  if (s.exclusiveMaximum !== undefined && v >= s.exclusiveMaximum) return `${s.title || title} must be less than ${s.exclusiveMaximum}${unit} (got ${text})`;
  if (s["x-odd"] && Math.abs(v % 2) !== 1) return `${s.title || title} must be odd (got ${text}): try ${v + 1} or ${v - 1}`;
  return "";
}

function clearFieldError(field) {
  field.classList.remove("invalid");
  field.querySelectorAll(".invalid").forEach((n) => n.classList.remove("invalid"));
  field.querySelector("[aria-invalid]")?.removeAttribute("aria-invalid");
  const box = field.querySelector(".field-error");
  if (box) { box.hidden = true; box.textContent = ""; }
}

// Mark a field rejected: red, its one-line reason under it, read with it by screen readers.
function markField(field, message) {
  field.classList.add("invalid");
  const input = field.input || field.querySelector("#seed");
  if (input) {
    input.classList.add("invalid");
    input.setAttribute("aria-invalid", "true");
  }
  const box = field.querySelector(".field-error");
  if (box) { box.hidden = false; box.textContent = message; }
}

function focusField(field) {
  const advanced = field.closest("details");
  if (advanced) advanced.open = true;
  const target = field.querySelector("input:not([type=hidden]), select") || field;
  target.focus();
  field.scrollIntoView({ block: "center" });
}

function clearErrors() {
  document.querySelectorAll(".field.invalid").forEach(clearFieldError);
  document.querySelectorAll(".invalid").forEach((n) => n.classList.remove("invalid"));
  const box = $("#form-error");
  if (box) box.hidden = true;
}

// Every field checked; the bad ones marked, the first focused. True when the form may be sent.
function checkForm() {
  clearErrors();
  const bad = [];
  for (const field of formFields($("#job-form"))) {
    const message = checkField(field);
    if (message) { markField(field, message); bad.push([field, message]); }
  }
  const seed = $("#seed");
  if (seed.value !== "" && !(/^\d+$/.test(seed.value) && Number(seed.value) <= 4294967295)) {
    const field = seed.closest(".field");
    const message = `Seed must be a whole number from 0 to 4294967295 (got ${seed.value})`;
    markField(field, message);
    bad.push([field, message]);
  }
  if (!bad.length) return true;
  showFormError(bad.length === 1 ? bad[0][1] : `${bad.length} fields need a change: ${bad.map((b) => b[1]).join("; ")}`);
  focusField(bad[0][0]);
  return false;
}

function showFormError(message) {
  const box = $("#form-error");
  if (!box) return;
  box.hidden = false;
  box.textContent = message;
}

function showMethod() {
  const m = methods.find((x) => x.name === $("#method").value);
  if (!m) return;
  $("#method-summary").textContent = `${m.summary}${m.paper ? " — " + m.paper : ""}`;
  for (const id of ["#size-fields", "#basic-fields", "#advanced-fields"]) $(id).replaceChildren();
  buildFields(m.size_schema, $("#size-fields"), null);
  buildFields(m.params_schema, $("#basic-fields"), $("#advanced-fields"));
  const more = $("#advanced-fields").children.length;
  $("#advanced-box").hidden = more === 0;
  $("#advanced-box").open = false;
  $("#advanced-count").textContent = `(${more} more parameter${more === 1 ? "" : "s"}, each with its default)`;
  clearErrors();
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

// Put a fetched image into a file field, as if the person had chosen it.
function setFile(input, blob, name) {
  const files = new DataTransfer();
  files.items.add(new File([blob], name, { type: blob.type || "image/png" }));
  input.files = files.files;
  input.dispatchEvent(new Event("change"));
}

// -- the examples gallery: bundled exemplars (credited), one click to use -------------------------
async function showExamples(gen) {
  let examples;
  try {
    examples = await api("/api/examples");
  } catch (err) {
    return; // a service without examples: no gallery
  }
  if (gen !== generation || !$("#examples")) return;
  examples = Array.isArray(examples) ? examples : examples.data || [];
  $("#examples").hidden = !examples.length;
  $("#example-list").replaceChildren(...examples.map((x) => {
    const button = el("button", { type: "button", class: "example", "data-example": x.name,
      "aria-label": `use the example ${x.title}${x.suggested_method ? ` with ${x.suggested_method}` : ""}` },
    el("img", { src: x.thumbnail, alt: "" }), el("span", { class: "example-title", text: x.title.split(" (")[0], title: x.title }));
    button.addEventListener("click", () => useExample(x, button));
    return el("li", {}, button, el("span", { class: "hint credit", text: `${x.credit}${x.licence ? ` (${x.licence})` : ""}` }));
  }));
}

async function useExample(x, button) {
  button.disabled = true;
  try {
    const resp = await authFetch(x.url);
    if (!resp.ok) throw new Error(`the example ${x.title} could not be fetched (HTTP ${resp.status})`);
    const blob = await resp.blob();
    if (!$("#job-form")) return;
    if (x.suggested_method && methods.some((m) => m.name === x.suggested_method) && x.kind !== "constraint") {
      $("#method").value = x.suggested_method;
      showMethod();
    }
    const role = x.kind === "constraint" ? "constraint" : "exemplar";
    setFile($(`#${role}`), blob, `${x.name}.png`);
    document.querySelectorAll(".example[aria-pressed]").forEach((b) => b.removeAttribute("aria-pressed"));
    button.setAttribute("aria-pressed", "true");
    $("#rerun-note").hidden = false;
    $("#rerun-note").textContent = `Example "${x.title}" is the ${role}` +
      (x.kind !== "constraint" && x.suggested_method ? `, with ${x.suggested_method}` : "") + ". Change anything, then submit.";
  } catch (err) {
    showFormError(err.message);
  } finally {
    button.disabled = false;
  }
}

async function renderHome(fromJob, setParam) {
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
  // a field's error goes as soon as it is edited; the constraints are checked again on leaving it
  $("#job-form").addEventListener("input", (event) => {
    const field = event.target.closest(".field");
    if (field && field.classList.contains("invalid")) clearFieldError(field);
  });
  $("#job-form").addEventListener("focusout", (event) => {
    const field = event.target.closest(".field[data-kind]");
    // leaving for a button: the submit checks everything (marking now would move the button away
    // between the press and the release of the mouse)
    if (!field || (event.relatedTarget && event.relatedTarget.matches("button"))) return;
    const message = checkField(field);
    if (message) markField(field, message);
  });
  $("#sweep-param").addEventListener("change", () => sweepSuggest());
  for (const input of document.querySelectorAll("#sweep-box input")) input.addEventListener("input", sweepPreview);
  $("#sweep-submit").addEventListener("click", submitSweep);
  setupJobList(gen);
  try {
    methods = (await api("/api/methods")).data;
  } catch (err) {
    showFormError(err.message);
    return;
  }
  if (gen !== generation) return;
  for (const m of methods) {
    $("#method").append(el("option", { value: m.name, text: m.name }));
    $("#filter-method").append(el("option", { value: m.name, text: m.name }));
  }
  const preferred = methods.find((m) => m.name === "wei-levoy");
  if (preferred) $("#method").value = preferred.name;
  showMethod();
  showExamples(gen);
  if (fromJob) await fillFromJob(fromJob, setParam);
}

// The service's refusal: a 422's fields ({loc: [..., FIELD], msg}) marked, the first focused; or its
// one-line message (err.field names the field in the older answers).
function showError(err, target) {
  clearErrors();
  const rejected = [];
  const names = formFields(document).map((f) => f.dataset.name).sort((a, b) => b.length - a.length);
  for (const e of err.errors || []) {
    let name = e.field;
    // an older answer names 'params' and the parameter only in its text
    if (name === "params") name = names.find((n) => new RegExp(`\\b${n}\\b`).test(e.msg)) || name;
    const field = document.querySelector(`.field[data-name="${name}"]`);
    if (field) {
      markField(field, e.msg);
      rejected.push(field);
    }
  }
  showFormError(err.message);
  if (target) {
    target.classList.add("invalid");
    target.focus();
  } else if (rejected.length) {
    focusField(rejected[0]);
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

const formParams = () => ({ ...readFields($("#basic-fields")), ...readFields($("#advanced-fields")) });
const formSize = () => readFields($("#size-fields"));

async function submitJob(event) {
  event.preventDefault();
  if (!checkForm()) return;
  const needed = [...document.querySelectorAll("#job-form input[type=file]")]
    .find((i) => i.required && !i.files.length && !i.closest("[hidden]"));
  if (needed) {
    showFormError(`choose the ${needed.id.replace("_", " ")} image (or click an example)`);
    needed.focus();
    return;
  }
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
// fetched back from the service and put into the file fields (so nothing needs re-choosing). From a
// sweep's "use this value", `setParam` names the swept parameter whose value was chosen.
async function fillFromJob(id, setParam) {
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
  for (const [name, value] of Object.entries({ ...job.size, ...job.params })) setFieldValue(name, value);
  if (job.voxel_size) {
    setFieldValue("voxel_size", job.voxel_size);
    if (job.voxel_unit) setFieldValue("voxel_unit", job.voxel_unit);
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
      setFile(input, blob, `${role}-${short(id)}.${ext}`);
      reused.push(role.replace("_", " "));
    } catch (err) {
      missing.push(role.replace("_", " "));
    }
  }
  const chosen = setParam && setParam in { ...job.size, ...job.params }
    ? `${setParam} = ${JSON.stringify({ ...job.size, ...job.params }[setParam])} (chosen in the sweep)` : "";
  if (chosen) {
    const field = document.querySelector(`.field[data-name="${setParam}"]`);
    if (field) {
      if (field.closest("details")) field.closest("details").open = true;
      field.classList.add("chosen");
    }
  }
  note.hidden = false;
  note.textContent = `The settings of job ${short(id)} are filled in (method, size, seed ${job.seed}, parameters${chosen ? "; " + chosen : ""})` +
    (reused.length ? `; its ${reused.join(", ")} reused` : "") +
    (missing.length ? `; choose the ${missing.join(", ")} again (the browser could not fetch them)` : "") +
    ". Change anything, then submit.";
}

// -- the sweep form: one parameter over a list or a range of values, times a list of seeds -----------

function sweepChoices() {
  const select = $("#sweep-param");
  if (!select) return;
  const fields = formFields($("#job-form")).filter((f) => !["array", "list"].includes(f.dataset.kind));
  select.replaceChildren(...fields.map((f) => el("option", { value: f.dataset.name, text: f.dataset.name })));
  const preferred = fields.find((f) => !f.closest("#size-fields") && ["integer", "number"].includes(f.dataset.kind));
  if (preferred) select.value = preferred.dataset.name;
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
    const odd = input.closest(".field")?.schema?.["x-odd"];
    const round = (x) => (odd ? 2 * Math.floor(x / 2) + 1 : Math.round(x));
    values = kind === "integer" ? [Math.max(Number(input.min || 1), round(v / 2)), v, round(v * 2)] : [v / 2, v, v * 2];
    if (input.max !== "") values = values.filter((x) => x <= Number(input.max));
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
  if (!checkForm()) return;
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

// -- the job list: thumbnails, method and exemplar, filter by method and state, delete, paging -------
const PAGE_SIZE = 12;
let jobsOffset = 0;
let jobsRequest = 0; // only the latest request's answer is shown (filters change while one is on its way)

function setupJobList(gen) {
  jobsOffset = 0;
  const again = () => { jobsOffset = 0; refreshJobs(gen, true); };
  $("#filter-method").addEventListener("change", again);
  $("#filter-state").addEventListener("change", again);
  $("#jobs-prev").addEventListener("click", () => { jobsOffset = Math.max(0, jobsOffset - PAGE_SIZE); refreshJobs(gen, true); });
  $("#jobs-next").addEventListener("click", () => { jobsOffset += PAGE_SIZE; refreshJobs(gen, true); });
  refreshJobs(gen);
}

const exemplarName = (j) => j.exemplar_name ?? j.exemplar_filename ?? j.filename ?? (j.input_names || {}).exemplar ?? "";

async function deleteJob(j, button) {
  const running = ["queued", "running"].includes(j.state);
  if (!confirm(running ? `Cancel job ${short(j.id)}?` : `Delete job ${short(j.id)} and its files?`)) return;
  button.disabled = true;
  try {
    await api(`/api/jobs/${j.id}`, { method: "DELETE" });
  } catch (err) {
    $("#jobs-count").textContent = err.message;
  }
  refreshJobs(generation, true);
}

async function refreshJobs(gen = generation, now = false) {
  const tbody = $("#jobs-table tbody");
  if (!tbody || gen !== generation) return;
  if (now && timer) clearTimeout(timer);
  const query = new URLSearchParams({ limit: PAGE_SIZE, offset: jobsOffset });
  if ($("#filter-method").value) query.set("method", $("#filter-method").value);
  if ($("#filter-state").value) query.set("state", $("#filter-state").value);
  const request = ++jobsRequest;
  try {
    const { data, count } = await api(`/api/jobs?${query}`);
    if (gen !== generation || request !== jobsRequest) return;
    // an older service ignores ?method=: filter here too
    const rows = data.filter((j) => !query.get("method") || j.method === query.get("method"));
    tbody.replaceChildren(...rows.map((j) => {
      // the service's thumbnail URL (signed); the output or the exemplar for an older service
      const thumbSrc = j.thumbnail || (j.state === "succeeded" ? j.artifacts?.["output.png"] : j.inputs?.exemplar);
      const name = exemplarName(j);
      const action = el("button", { type: "button", class: "link danger", text: ["queued", "running"].includes(j.state) ? "cancel" : "delete",
        "aria-label": `${["queued", "running"].includes(j.state) ? "cancel" : "delete"} job ${short(j.id)}` });
      action.addEventListener("click", () => deleteJob(j, action));
      return el("tr", { "data-job": j.id },
        el("td", {}, thumbSrc ? el("a", { href: `#/jobs/${j.id}`, tabindex: "-1" },
          el("img", { class: "thumb", src: thumbSrc, alt: "", loading: "lazy" })) : ""),
        el("td", {}, el("a", { href: `#/jobs/${j.id}`, text: short(j.id) }),
          j.sweep_id ? el("a", { href: `#/sweeps/${j.sweep_id}`, class: "hint sweep-tag", text: " sweep" }) : ""),
        el("td", {}, el("span", { text: j.method }), name ? el("span", { class: "hint exemplar-name", text: ` · ${name}` }) : ""),
        el("td", { text: sizeOf(j) }),
        el("td", {}, el("span", { class: `state ${j.state}`, text: j.state })),
        j.state === "failed"
          ? el("td", { class: "reason", title: j.message, text: j.message })
          : el("td", { text: j.state === "running" ? `${Math.round(100 * j.fraction)}%` : "" }),
        el("td", { text: fmtTime(j.created) }),
        el("td", {}, action));
    }));
    const total = typeof count === "number" ? count : jobsOffset + data.length;
    $("#jobs-count").textContent = total ? `${total} job${total === 1 ? "" : "s"}` : "no jobs yet";
    $("#jobs-page").textContent = data.length ? `${jobsOffset + 1}–${jobsOffset + data.length} of ${total}` : "";
    $("#jobs-prev").disabled = jobsOffset === 0;
    $("#jobs-next").disabled = jobsOffset + data.length >= total;
  } catch (err) { /* the next refresh retries */ }
  if (gen === generation) {
    if (timer) clearTimeout(timer);
    timer = setTimeout(() => refreshJobs(gen), 3000);
  }
}

// #/jobs: the list alone
function renderJobList() {
  const gen = generation;
  $("#view").replaceChildren($("#tpl-home").content.cloneNode(true));
  $("#submit-card").remove();
  setupJobList(gen);
  api("/api/methods").then(({ data }) => {
    if (gen !== generation) return;
    for (const m of data) $("#filter-method").append(el("option", { value: m.name, text: m.name }));
  }).catch(() => {});
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
    $("#job-summary").textContent = `${job.method}, ${sizeOf(job)}${voxelText(job) ? ` (${voxelText(job)})` : ""}, seed ${job.seed} — submitted ${fmtTime(job.created)}` +
      (job.elapsed ? `, ${job.elapsed.toFixed(1)} s` : "") + (job.attempts > 1 ? `, run ${job.attempts}` : "");
    // a cancelled job keeps the bar where it stopped (grey); an older record that says 1.0 shows none
    const cancelled = job.state === "cancelled";
    const stopped = cancelled && job.fraction >= 1 ? 0 : job.fraction;
    $("#progress").value = job.state === "succeeded" ? 1 : stopped;
    $("#progress").classList.toggle("failed", job.state === "failed");
    $("#progress").classList.toggle("cancelled", cancelled);
    const stage = ["failed", "cancelled", "done"].includes(job.stage) ? "" : job.stage;
    const pct = Math.round(100 * job.fraction);
    $("#progress-text").textContent = job.state === "failed"
      ? `failed at ${pct}%${stage ? ` during ${stage}` : ""}: the reason is below`
      : cancelled ? `cancelled${job.fraction < 1 && job.fraction > 0 ? ` at ${pct}%` : ""}${stage ? ` during ${stage}` : ""}`
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

// A volume's voxel size ("voxel 0.055 nm"), or that it is uncalibrated; "" for an image.
function voxelText(job) {
  if (!job.size || !job.size.depth) return "";
  const size = job.voxel_size ?? job.params?.voxel_size ?? job.size?.voxel_size;
  const unit = job.voxel_unit ?? job.params?.voxel_unit ?? job.size?.voxel_unit ?? "";
  return size ? `voxel ${size} ${unit}`.trim() : "voxels uncalibrated";
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
  // the tensor images, the exemplar's in its column beside the output's
  const tensors = [["coherence", "coherence.png"], ["orientation", "orientation.png"],
    ["ex-coherence", "exemplar-coherence.png"], ["ex-orientation", "exemplar-orientation.png"]];
  for (const [kind, name] of tensors) {
    // a missing exemplar image keeps its place, so the output's stay under the output
    if (kind.startsWith("ex-")) $(`#fig-${kind}`).classList.toggle("absent", !a[name]);
    else $(`#fig-${kind}`).hidden = !a[name];
    $(`#fig-${kind}`).hidden = kind.startsWith("ex-") ? false : !a[name];
    if (a[name]) $(`#view-${kind}`).src = a[name];
  }
  $("#coherence-row").hidden = !a["coherence.png"] && !a["exemplar-coherence.png"];
  $("#orientation-row").hidden = !a["orientation.png"] && !a["exemplar-orientation.png"];
  $("#tensor-legends").hidden = $("#coherence-row").hidden && $("#orientation-row").hidden;
  const layout = () => {
    if (!tiles.isConnected) return; // an image loaded after the page was left
    const tiled = $("#tile").checked;
    tiles.classList.toggle("tiled", tiled);
    tiles.querySelectorAll(".tile-copy").forEach((img) => { img.hidden = !tiled; });
    const exW = exemplar.naturalWidth || 0;
    const exH = exemplar.naturalHeight || 0;
    const outW = tiled ? 2 * W : W;
    const outH = tiled ? 2 * H : H;
    const choice = radioValue("zoom");
    // fit: exemplar and output side by side within the width and 60 % of the window's height; the
    // stage then grows with the page (no box of its own), so the tensor rows and the legends below
    // are never cut off; zoomed in, the stage scrolls in a box
    $("#stage").classList.toggle("zoomed", choice !== "fit");
    const box = $("#stage").clientWidth - 60;
    const scale = zoomScale(choice, exW + outW, Math.max(exH, outH), box, 0.6 * window.innerHeight);
    setSize(exemplar, exW * scale, exH * scale);
    tiles.querySelectorAll("img").forEach((img) => setSize(img, W * scale, H * scale));
    // The tensor images carry their legend below (and are padded to its width): show only the
    // image-sized part, at the common scale; the page draws the legends once, below the stage.
    for (const [kind] of tensors) {
      const img = $(`#view-${kind}`);
      const [w, h] = kind.startsWith("ex-") ? [exW, exH] : [W, H];
      setSize(img.parentElement, w * scale, h * scale);
      if (img.naturalWidth) setSize(img, img.naturalWidth * scale, img.naturalHeight * scale);
    }
    // one column for the exemplar and its tensor images, one for the output and its: rows line up
    const column = Math.max(exW * scale, 120);
    for (const fig of [exemplar.closest("figure"), $("#fig-ex-coherence"), $("#fig-ex-orientation")]) setSize(fig, column);
    const px = (n) => Math.round(n * scale);
    $("#cap-exemplar").textContent = `exemplar ${exW}×${exH}`;
    $("#cap-output").textContent = `output ${W}×${H}${tiled ? ", tiled 2×2: look for seams along the middle lines" : ""}`;
    const label = { fit: "fit", 1: "1:1", 2: "2x", 4: "4x" }[choice];
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

// A volume's three orthogonal slices at once through one point (x, y, z), like Fiji's orthogonal
// views: xy (fixed z) with yz (fixed x) beside it, transposed so that y runs down in both, and xz
// (fixed y) below it, so that x runs right in both. A click on any slice moves the shared crosshair;
// the sliders do too; zoom and contrast apply to all three.
function showVolumeViewer(job) {
  const depth = job.size.depth;
  $("#volume-viewer").hidden = !depth;
  if (!depth) return;
  const W = job.size.width;
  const H = job.size.height;
  const D = depth;
  const extent = { x: W, y: H, z: D };
  const pos = { x: Math.floor(W / 2), y: Math.floor(H / 2), z: Math.floor(D / 2) };
  for (const axis of ["x", "y", "z"]) {
    const slider = $(`#pos-${axis}`);
    slider.max = extent[axis] - 1;
    slider.value = pos[axis];
    slider.setAttribute("aria-label", `${axis} position of the crosshair, 0 to ${extent[axis] - 1}`);
    slider.addEventListener("input", () => { pos[axis] = Number(slider.value); show(); });
  }
  // the plane's slice index, and its image's (u, v) axes as shown
  const planes = {
    xy: { index: "z", u: "x", v: "y", w: W, h: H },
    xz: { index: "y", u: "x", v: "z", w: W, h: D },
    yz: { index: "x", u: "z", v: "y", w: D, h: H, transposed: true },
  };
  const fits = (s) => (W + D) * s + 40 <= $("#volume-viewer").clientWidth;
  const start = [8, 4, 2, 1].find(fits) || 1;
  document.querySelector(`input[name=ortho-zoom][value="${start}"]`).checked = true;
  let shown = {};
  const show = () => {
    if (!$("#volume-viewer") || !$("#volume-viewer").isConnected) return;
    const scale = Number(radioValue("ortho-zoom"));
    const contrast = Number($("#ortho-contrast").value);
    $("#ortho-contrast-label").textContent = `${contrast}×`;
    const cross = $("#ortho-cross").checked;
    for (const [plane, p] of Object.entries(planes)) {
      const img = $(`#ortho-${plane}`);
      const box = $(`#box-${plane}`);
      const index = pos[p.index];
      if (shown[plane] !== index) {
        img.src = signed(`/api/jobs/${job.id}/slices/${plane}/${index}.png`, job.access);
        shown[plane] = index;
      }
      setSize(box, p.w * scale, p.h * scale);
      // yz is served with y right and z down: transposed, z runs right and y down
      if (p.transposed) setSize(img, p.h * scale, p.w * scale);
      else setSize(img, p.w * scale, p.h * scale);
      img.style.filter = contrast === 1 ? "" : `contrast(${contrast})`;
      const h = $(".cross-h", box);
      const v = $(".cross-v", box);
      h.hidden = v.hidden = !cross;
      v.style.left = `${(pos[p.u] + 0.5) * scale}px`;
      h.style.top = `${(pos[p.v] + 0.5) * scale}px`;
      $(`#cap-${plane}`).textContent = `${plane} slice at ${p.index} = ${index}` +
        (p.transposed ? " (z right, y down)" : ` (${p.u} right, ${p.v} down)`);
    }
    for (const axis of ["x", "y", "z"]) $(`#pos-${axis}`).value = pos[axis];
    $("#ortho-pos").textContent = `x = ${pos.x}, y = ${pos.y}, z = ${pos.z} (of ${W}×${H}×${D})`;
  };
  for (const [plane, p] of Object.entries(planes)) {
    $(`#box-${plane}`).addEventListener("click", (event) => {
      const rect = event.currentTarget.getBoundingClientRect();
      const scale = Number(radioValue("ortho-zoom"));
      const u = Math.floor((event.clientX - rect.left) / scale);
      const v = Math.floor((event.clientY - rect.top) / scale);
      pos[p.u] = Math.max(0, Math.min(extent[p.u] - 1, u));
      pos[p.v] = Math.max(0, Math.min(extent[p.v] - 1, v));
      show();
    });
  }
  document.querySelectorAll("input[name=ortho-zoom]").forEach((r) => r.addEventListener("change", show));
  $("#ortho-contrast").addEventListener("input", show);
  $("#ortho-cross").addEventListener("change", show);
  show();
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

// A measure's direction in the service's words ("lower", "higher", "near-1", "abs-lower"): from the
// job's own verdict when it has one, else from the glossary (a signed difference is judged by its size).
function directionOf(name, m) {
  if (!m) return "lower";
  if (m.direction) return m.direction;
  if (m.better === "closer to 1") return "near-1";
  if (m.better === "higher") return "higher";
  return /_difference$/.test(name) ? "abs-lower" : "lower";
}
const DIRECTION_TEXT = { lower: "lower is better", higher: "higher is better", "near-1": "closer to 1 is better",
  "abs-lower": "closer to 0 is better (the sign says which way)" };

function targetText(target, direction) {
  if (target === null || target === undefined) return "";
  if (Array.isArray(target)) return `${fmtNum(target[0])}–${fmtNum(target[1])}`;
  if (typeof target !== "number") return String(target);
  return { lower: `< ${target}`, higher: `> ${target}`, "abs-lower": `|value| < ${target}`, "near-1": `1 ± ${target}` }[direction] || String(target);
}

// A value against its measure's documented target: "good", "near", "off", or "" (no target).
function verdictOf(m, value, name = "") {
  if (!m || m.good_below === null || m.good_below === undefined || typeof value !== "number") return "";
  const direction = directionOf(name, m);
  const size = direction === "near-1" ? Math.abs(value - 1) : direction === "lower" ? value : Math.abs(value);
  if (direction === "higher") return value > m.good_below ? "good" : "off";
  return size < m.good_below ? "good" : "off";
}
const VERDICT_CLASS = { meets: "good", near: "near", misses: "off", good: "good", off: "off" };
const VERDICT_TEXT = { good: "meets the target", near: "near the target", off: "misses the target" };

// The headline measures of a job: [{name, value, target, direction, verdict}], from the service's own
// verdicts ({value, target, direction, verdict} per measure) or, for older records, the glossary.
function headline(metrics, g) {
  const judged = (metrics && metrics.headline) || {};
  // the service's verdicts when it gives them (metrics.headline), else the summary judged here
  const summary = Object.keys(judged).length ? judged : (metrics && metrics.summary) || {};
  const out = [];
  for (const [name, raw] of Object.entries(summary)) {
    const entry = raw && typeof raw === "object" && "value" in raw ? raw : judged[name];
    const value = entry ? entry.value : raw;
    if (typeof value !== "number") continue;
    const m = g[name];
    if (entry && "verdict" in entry) {
      out.push({ name, value, target: entry.target, direction: entry.direction || directionOf(name, m),
        verdict: VERDICT_CLASS[entry.verdict] ?? "" });
    } else {
      out.push({ name, value, target: m ? m.good_below : null, direction: directionOf(name, m), verdict: verdictOf(m, value, name) });
    }
  }
  return out;
}

const isFringeMeasure = (name) => name.startsWith("fringe_");
const fringesHidden = (metrics) => metrics && metrics.fringes && metrics.fringes.shown === false;

// One row per headline measure: value, target, a verdict against it, and what it says.
async function showMetrics(metrics) {
  const g = await measures();
  if (!$("#metrics")) return; // the page was left while the glossary loaded
  const hidden = fringesHidden(metrics);
  const rows = headline(metrics, g).filter((h) => !(hidden && isFringeMeasure(h.name))).map((h) => {
    const m = g[h.name];
    const target = targetText(h.target, h.direction);
    return el("tr", { "data-measure": h.name }, el("th", { text: m ? m.label : h.name }), el("td", { class: "num", text: fmtNum(h.value) }),
      el("td", { text: target || "no documented target" , class: target ? "" : "hint" }),
      el("td", {}, el("span", { class: `verdict ${h.verdict}`, text: VERDICT_TEXT[h.verdict] || "—" })),
      el("td", { class: "hint", text: m ? `${m.meaning}; ${DIRECTION_TEXT[h.direction] || `${m.better} is better`}` : DIRECTION_TEXT[h.direction] || "" }));
  });
  $("#metrics tbody").replaceChildren(...rows);
  $("#fringe-note").hidden = !hidden;
  if (hidden) {
    $("#fringe-note").textContent = `Fringe measures are not shown: ${metrics.fringes.reason || "the exemplar has no lattice fringes"}.`;
  }
  // A volume: the same measures per axis (the slices normal to z, y and x: the xy, xz and yz planes).
  const perAxis = metrics && metrics.summary && metrics.summary.per_axis;
  $("#axis-metrics").hidden = !perAxis;
  if (!perAxis) return;
  const axes = [["0", "xy slices"], ["1", "xz slices"], ["2", "yz slices"]].filter(([a]) => perAxis[a]);
  $("#axis-metrics thead").replaceChildren(el("tr", {}, el("th", { text: "measure" }),
    ...axes.map(([, label]) => el("th", { text: label }))));
  const valueOf = (v) => (v && typeof v === "object" && "value" in v ? v.value : v);
  const names = Object.keys(perAxis[axes[0][0]]).filter((n) => typeof valueOf(perAxis[axes[0][0]][n]) === "number")
    .filter((n) => !(hidden && isFringeMeasure(n)));
  $("#axis-metrics tbody").replaceChildren(...names.map((name) => {
    const m = g[name];
    return el("tr", {}, el("th", { text: m ? m.label : name, title: m ? m.meaning : "" }),
      ...axes.map(([a]) => {
        const raw = perAxis[a][name];
        const v = valueOf(raw);
        const verdict = raw && typeof raw === "object" && raw.verdict ? VERDICT_CLASS[raw.verdict] : verdictOf(m, v, name);
        return el("td", { class: `num verdict ${verdict || ""}`, text: fmtNum(v), title: VERDICT_TEXT[verdict] || "" });
      }));
  }));
}

// The exemplar's fringe statistics beside the output's, so a number is read against the sample's own.
const FRINGE_STATS = [["count", "fringes"], ["mean_length", "mean length (px)"], ["median_length", "median length (px)"],
  ["mean_tortuosity", "mean tortuosity"], ["share_tortuous", "share tortuous"], ["density_per_10k_px", "per 10k px"]];
function showFringes(fringes) {
  const ok = fringes && fringes.shown !== false && fringes.exemplar && fringes.output;
  $("#fringe-metrics").hidden = !ok;
  if (!ok) return;
  const cell = (side, k) => el("td", { class: "num", text: k in side ? fmtNum(side[k]) : "—" });
  $("#fringe-metrics tbody").replaceChildren(...FRINGE_STATS.filter(([k]) => k in fringes.exemplar || k in fringes.output)
    .map(([k, label]) => el("tr", {}, el("th", { text: label }), cell(fringes.exemplar, k), cell(fringes.output, k))));
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
  // A 2-D output, its exemplar and the tensor images go to the viewer; a volume keeps its pictures.
  $("#viewer").hidden = volume || !a["output.png"];
  if (!$("#viewer").hidden) showViewer(job);
  const inViewer = volume ? new Set()
    : new Set(["output.png", "coherence.png", "orientation.png", "exemplar-coherence.png", "exemplar-orientation.png"]);
  const captions = { "cube.png": "the volume: outer faces and a corner cut away", "output.png": volume ? "output (middle xy slice)" : "output",
    "slices.png": "mid-slices beside their exemplars",
    "exemplar-coherence.png": "coherence (exemplar)", "coherence.png": "coherence (output)",
    "exemplar-orientation.png": "orientation (exemplar)", "orientation.png": "orientation (output)",
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
  showMetrics(job.metrics && job.metrics.summary ? job.metrics : { summary: Object.fromEntries(metrics) });
  showFringes(job.metrics && job.metrics.fringes);
  $("#all-metrics tbody").replaceChildren(...metrics.map(row));
  $("#plots").replaceChildren(...Object.keys(a).filter((n) => n.startsWith("plots/"))
    .filter((n) => !(fringesHidden(job.metrics) && /fringe/.test(n)))
    .map((n) => figure(a[n], n.slice(6).replace(".png", "").replaceAll("_", " "))));
  // everything in one zip, then each file
  const zip = job.artifacts_zip || signed(`/api/jobs/${job.id}/artifacts.zip`, job.access); // the service's is signed
  $("#zip-link").hidden = false;
  $("#zip-link").href = zip;
  $("#zip-link").setAttribute("download", `texsynth-${short(job.id)}.zip`);
  $("#voxel-note").hidden = !volume;
  $("#voxel-note").textContent = volume ? `output.tiff: ${voxelText(job)}` +
    (voxelText(job) === "voxels uncalibrated" ? " (give a voxel size in the form to calibrate it in Fiji)" : " (Fiji reads it as the calibration)") : "";
  $("#downloads").replaceChildren(el("li", {}, el("a", { href: zip, download: `texsynth-${short(job.id)}.zip`, text: "all artifacts (zip)", id: "zip-download" })),
    ...Object.entries(a).map(([n, url]) => el("li", {}, el("a", { href: url, download: n.replace("plots/", ""), text: n }))));
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
function better(direction, a, b) {
  if (typeof a !== "number" || typeof b !== "number" || a === b) return "";
  const score = (v) => (direction === "higher" ? -v : direction === "near-1" ? Math.abs(v - 1) : direction === "lower" ? v : Math.abs(v));
  return score(a) < score(b) ? "A" : score(b) < score(a) ? "B" : "";
}

async function compareMetrics(A, B) {
  const g = await measures();
  const byName = (job) => Object.fromEntries(headline(job.metrics, g)
    .filter((h) => !(fringesHidden(job.metrics) && isFringeMeasure(h.name))).map((h) => [h.name, h]));
  const ha = byName(A);
  const hb = byName(B);
  const names = [...new Set([...Object.keys(ha), ...Object.keys(hb)])];
  if (!$("#compare-metrics")) return;
  const cell = (h) => el("td", { class: `num verdict ${h ? h.verdict : ""}`, text: h ? fmtNum(h.value) : "—",
    title: h && h.verdict ? `${VERDICT_TEXT[h.verdict]} (${targetText(h.target, h.direction)})` : "" });
  $("#compare-metrics tbody").replaceChildren(...names.map((name) => {
    const m = g[name];
    const h = ha[name] || hb[name];
    const who = better(h.direction, ha[name]?.value, hb[name]?.value);
    return el("tr", {}, el("th", { text: m ? m.label : name, title: m ? m.meaning : "" }),
      cell(ha[name]), cell(hb[name]),
      el("td", { text: who ? `${who} (${DIRECTION_TEXT[h.direction] || "lower is better"})` : "same" }));
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
  sweepSort = { key: null, dir: 1 };
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

let sweepSort = { key: null, dir: 1 };

const mean = (xs) => xs.reduce((a, b) => a + b, 0) / xs.length;
// the sample standard deviation; rounding noise of equal values (1e-17) reads as 0
const spread = (xs) => {
  if (xs.length < 2) return 0;
  const m = mean(xs);
  const sd = Math.sqrt(xs.reduce((a, x) => a + (x - m) ** 2, 0) / (xs.length - 1));
  return sd <= 1e-9 * Math.max(...xs.map(Math.abs)) ? 0 : sd;
};

// One row per value of the swept parameter: every measure's mean ± standard deviation over the seeds,
// the best value by the chosen measure marked, and "use this value" that fills the form with it.
function drawRanking(rows, param, metricCols, chosen, g) {
  const values = [...new Set(rows.map((r) => JSON.stringify(r[param])))].map((v) => JSON.parse(v));
  const name = (c) => c.slice(8);
  const label = (c) => g[name(c)]?.label || name(c);
  const stats = values.map((value) => {
    const runs = rows.filter((r) => JSON.stringify(r[param]) === JSON.stringify(value));
    const done = runs.filter((r) => r.state === "succeeded");
    const cols = Object.fromEntries(metricCols.map((c) => {
      const xs = done.map((r) => r[c]).filter((x) => typeof x === "number");
      return [c, xs.length ? { mean: mean(xs), sd: spread(xs), n: xs.length } : null];
    }));
    return { value, runs, done, cols };
  });
  const direction = chosen ? directionOf(name(chosen), g[name(chosen)]) : "lower";
  const score = (v) => (direction === "higher" ? -v : direction === "near-1" ? Math.abs(v - 1) : direction === "lower" ? v : Math.abs(v));
  const ranked = stats.filter((s) => chosen && s.cols[chosen]);
  const best = ranked.length ? ranked.reduce((a, b) => (score(b.cols[chosen].mean) < score(a.cols[chosen].mean) ? b : a)) : null;
  const seedsPer = Math.max(0, ...stats.map((s) => s.runs.length));
  $("#ranking-hint").textContent = chosen
    ? `mean ± standard deviation over ${seedsPer} seed${seedsPer === 1 ? "" : "s"}; best by ${label(chosen)} (${DIRECTION_TEXT[direction]}) marked ★`
    : "waiting for the first finished run";
  // the chosen measure first, then the others
  const cols = chosen ? [chosen, ...metricCols.filter((c) => c !== chosen)] : metricCols;
  $("#sweep-ranking thead").replaceChildren(el("tr", {}, el("th", { text: param }),
    el("th", {}, el("span", { class: "visually-hidden", text: "fill the form" })), el("th", { text: "runs done" }),
    ...cols.map((c) => el("th", { text: label(c), class: c === chosen ? "chosen" : "" }))));
  $("#sweep-ranking tbody").replaceChildren(...stats.map((s) => {
    const isBest = s === best;
    const use = el("button", { type: "button", class: "secondary use-value", text: "use this value",
      "aria-label": `use ${param} = ${s.value} in the form` });
    use.disabled = !s.done.length;
    use.addEventListener("click", () => { location.hash = `#/new?from=${s.done[0].job}&set=${encodeURIComponent(param)}`; });
    return el("tr", { class: isBest ? "best" : "", "data-value": JSON.stringify(s.value) },
      el("th", { class: "nowrap" }, String(s.value), isBest ? el("span", { class: "best-mark", text: " ★ best" }) : ""),
      el("td", {}, use),
      el("td", { class: "num nowrap", text: `${s.done.length} of ${s.runs.length}` }),
      ...cols.map((c) => {
        const st = s.cols[c];
        const m = g[name(c)];
        return el("td", { class: `num verdict ${st ? verdictOf(m, st.mean, name(c)) : ""}`,
          text: st ? `${fmtNum(st.mean)}${st.n > 1 ? ` ± ${fmtNum(st.sd)}` : ""}` : "" });
      }));
  }));
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
  drawRanking(rows, param, metricCols, chosen, g);
  // every run, sortable by any column (a click on its name; again: the other way)
  const sort = sweepSort;
  const sortable = [["seed", "seed"], ...params.map((p) => [p, p]), ["state", "state"], ...metricCols.map((c) => [c, label(c)])];
  const header = (key, text, title = "") => {
    const dir = sort.key === key ? sort.dir : 0;
    const button = el("button", { type: "button", class: "sort", text, title });
    button.append(el("span", { class: "sort-mark", "aria-hidden": "true", text: dir > 0 ? " ▲" : dir < 0 ? " ▼" : "" }));
    button.addEventListener("click", () => {
      sweepSort = { key, dir: sort.key === key ? -sort.dir : 1 };
      drawSweep(sweeps, seeds, g);
    });
    return el("th", { "aria-sort": dir > 0 ? "ascending" : dir < 0 ? "descending" : "none", class: key === chosen ? "chosen" : "", "data-key": key }, button);
  };
  $("#sweep-table thead").replaceChildren(el("tr", {}, el("th", { text: "output" }),
    ...sortable.map(([key, text]) => header(key, text, g[String(key).slice(8)]?.meaning || ""))));
  if (sort.key) {
    const cmp = (a, b) => (typeof a === "number" && typeof b === "number" ? a - b : String(a ?? "").localeCompare(String(b ?? ""), undefined, { numeric: true }));
    rows.sort((a, b) => {
      const va = a[sort.key];
      const vb = b[sort.key];
      if (va === undefined || va === null) return 1; // unfinished runs last, either way
      if (vb === undefined || vb === null) return -1;
      return sort.dir * cmp(va, vb);
    });
  }
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
        return el("td", { class: `num verdict ${verdictOf(m, r[c], c.slice(8))}`, text: r[c] === undefined ? "" : fmtNum(r[c]) });
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
  else if (/^#\/jobs\/?$/.test(hash)) renderJobList();
  else {
    const query = new URLSearchParams(hash.split("?")[1] || "");
    renderHome(query.get("from"), query.get("set"));
  }
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
