// texsyn serve: the page. Plain JavaScript, no build step (docs/web.md).
"use strict";

const token = new URLSearchParams(location.search).get("token") || "";
const q = (id) => document.getElementById(id);
const state = { mode: "synth", methods: [], exemplar: null, job: null, source: null, limits: {} };

function withToken(url) {
  return url + (url.includes("?") ? "&" : "?") + "token=" + encodeURIComponent(token);
}

async function api(path, options = {}) {
  const headers = Object.assign({ "X-Texsyn-Token": token }, options.headers || {});
  const response = await fetch(path, Object.assign({}, options, { headers }));
  let body = null;
  try { body = await response.json(); } catch (e) { body = null; }
  if (!response.ok) {
    throw new Error((body && body.error) || `the server answered ${response.status}`);
  }
  return body;
}

function showError(message) {
  const box = q("error");
  box.textContent = message || "";
  box.hidden = !message;
}

function element(tag, attrs = {}, text = "") {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text) node.textContent = text;
  return node;
}

// ------------------------------------------------------------------ exemplar
function setExemplar(item) {
  state.exemplar = item;
  q("exemplar-preview").src = withToken(`/api/exemplars/${encodeURIComponent(item.id)}/preview`);
  q("exemplar-name").textContent = `${item.name} (${item.width}x${item.height})`;
  q("width").value = 2 * item.width;
  q("height").value = 2 * item.height;
  document.querySelectorAll("#builtins button").forEach((b) => b.classList.toggle("active", b.dataset.id === item.id));
}

async function upload(file) {
  showError("");
  const limit = state.limits.max_upload_bytes;
  if (limit && file.size > limit) {
    showError(`the file is ${(file.size / 1e6).toFixed(1)} MB, over the ${limit / 1e6} MB upload limit`);
    return;
  }
  q("exemplar-name").textContent = `uploading ${file.name}...`;
  try {
    const item = await api("/api/exemplars", {
      method: "POST",
      body: file,
      headers: { "X-Filename": encodeURIComponent(file.name), "Content-Type": "application/octet-stream" },
    });
    setExemplar(item);
  } catch (e) {
    q("exemplar-name").textContent = state.exemplar ? `${state.exemplar.name}` : "";
    showError(e.message);
  }
}

// ------------------------------------------------------------------ parameter form
function paramInput(method, spec) {
  const id = `p-${method}-${spec.name}`;
  const row = element("div", { class: "param" });
  const label = element("label", { for: id, title: spec.help }, spec.name);
  let input;
  if (spec.allowed && spec.allowed.choices) {
    input = element("select", { id });
    for (const c of spec.allowed.choices) input.append(element("option", { value: c }, c));
    if (spec.optional) input.append(element("option", { value: "none" }, "none"));
  } else if (spec.type === "bool") {
    input = element("select", { id });
    input.append(element("option", { value: "true" }, "true"), element("option", { value: "false" }, "false"));
  } else {
    input = element("input", { id, type: "text", inputmode: spec.type === "str" ? "text" : "decimal" });
  }
  input.value = spec.default;
  input.dataset.method = method;
  input.dataset.name = spec.name;
  input.dataset.default = spec.default;
  const help = element("small", {}, `${spec.help} (${spec.describe}; default ${spec.default})`);
  row.append(label, input, help);
  return row;
}

function buildParams() {
  const box = q("params");
  box.replaceChildren();
  const names = state.mode === "compare" ? checkedMethods() : state.mode === "animate" ? ["grouplets"] : [q("method").value];
  for (const name of names) {
    const method = state.methods.find((m) => m.name === name);
    if (!method) continue;
    const group = element("fieldset", { "data-method": name });
    group.append(element("legend", {}, name));
    for (const spec of method.params) group.append(paramInput(name, spec));
    box.append(group);
  }
  const current = state.methods.find((m) => m.name === q("method").value);
  q("method-summary").textContent = current ? `${current.summary} ${current.reference}` : "";
}

function changedParams(method) {
  const out = {};
  document.querySelectorAll(`#params [data-method="${method}"][data-name]`).forEach((input) => {
    if (input.value.trim() !== input.dataset.default) out[input.dataset.name] = input.value.trim();
  });
  return out;
}

function checkedMethods() {
  return Array.from(document.querySelectorAll("#compare-methods input:checked")).map((i) => i.value);
}

// ------------------------------------------------------------------ modes
function setMode(mode) {
  state.mode = mode;
  document.body.dataset.mode = mode;
  document.querySelectorAll("#modes button").forEach((b) => b.classList.toggle("active", b.dataset.mode === mode));
  q("params-box").open = mode !== "compare";  // several methods' forms: folded until asked for
  buildParams();
}

function newSeed() {
  const words = new Uint32Array(1);
  crypto.getRandomValues(words);
  q("seed").value = words[0];
}

// ------------------------------------------------------------------ jobs
function request() {
  const body = { mode: state.mode, exemplar: state.exemplar ? state.exemplar.id : "" };
  const w = parseInt(q("width").value, 10), h = parseInt(q("height").value, 10);
  if (Number.isFinite(w) && Number.isFinite(h)) body.size = [w, h];
  if (state.mode !== "compare" && q("seed").value !== "") body.seed = Number(q("seed").value);
  if (state.mode === "synth") {
    body.method = q("method").value;
    body.params = changedParams(body.method);
    body.metrics = q("measure").checked;
  } else if (state.mode === "compare") {
    body.methods = checkedMethods();
    body.params = {};
    for (const m of body.methods) {
      const p = changedParams(m);
      if (Object.keys(p).length) body.params[m] = p;
    }
  } else {
    body.frames = Number(q("frames").value);
    body.fps = Number(q("fps").value);
    body.params = changedParams("grouplets");
  }
  return body;
}

async function run() {
  showError("");
  if (!state.exemplar) { showError("choose an exemplar first"); return; }
  q("run").disabled = true;
  try {
    const job = await api("/api/jobs", {
      method: "POST",
      body: JSON.stringify(request()),
      headers: { "Content-Type": "application/json" },
    });
    if (job.seed !== null && job.seed !== undefined) q("seed").value = job.seed;
    follow(job);
  } catch (e) {
    showError(e.message);
    q("run").disabled = false;
  }
}

function follow(job) {
  if (state.source) state.source.close();
  state.job = job;
  q("result").hidden = true;
  q("cancel").disabled = false;
  showStatus(job);
  const source = new EventSource(withToken(`/api/jobs/${job.id}/events`));
  state.source = source;
  source.onmessage = (event) => {
    const current = JSON.parse(event.data);
    state.job = current;
    showStatus(current);
    if (["done", "failed", "cancelled"].includes(current.state)) {
      source.close();
      finished(current);
    } else if (Object.keys(current.files).length) {
      render(current);  // the output shows while the metrics are measured
    }
  };
}

function showStatus(job) {
  q("status").hidden = false;
  const bar = q("progress");
  let text = "";
  if (job.state === "queued") {
    text = `waiting in the queue: position ${job.position}`;
    bar.removeAttribute("value");
  } else if (job.state === "running") {
    const p = job.progress;
    if (job.step > 0) {
      text = "measuring the output";
      bar.removeAttribute("value");
    } else if (p && p.total > 0) {
      text = `${job.label}: ${p.stage} ${p.done}/${p.total}`;
      bar.value = p.done / p.total;
    } else {
      text = `${job.label}: starting`;
      bar.removeAttribute("value");
    }
    text += ` (${job.elapsed.toFixed(1)} s)`;
  } else if (job.state === "done") {
    text = `done in ${job.elapsed.toFixed(1)} s`;
    bar.value = 1;
  } else if (job.state === "cancelled") {
    text = "cancelled";
    bar.value = 0;
  } else {
    text = "failed";
    bar.value = 0;
  }
  q("status-text").textContent = text;
  q("status").dataset.state = job.state;
}

function finished(job) {
  q("run").disabled = false;
  q("cancel").disabled = true;
  if (job.state === "failed") { showError(job.error); return; }
  if (job.state === "done") render(job);
  if (job.warning) showError(job.warning);
}

function setSource(node, url) {
  if (node.dataset.url !== url) { node.dataset.url = url; node.src = url; }
}

function render(job) {
  const files = job.files;
  q("result").hidden = false;
  q("out-exemplar").src = withToken(`/api/exemplars/${encodeURIComponent(job.exemplar.id)}/preview`);
  const isSynth = job.mode === "synth", isCompare = job.mode === "compare", isVideo = job.mode === "animate";
  q("fig-output").hidden = !isSynth;
  q("fig-exemplar").hidden = isCompare;  // the report shows it
  q("fig-map").hidden = !(isSynth && files.map);
  q("fig-video").hidden = !isVideo;
  q("report").hidden = !isCompare;
  q("metrics").hidden = !(isSynth && job.metrics);
  if (isSynth) {
    if (files.image) setSource(q("out-image"), files.image.url + "&inline=1");
    q("out-caption").textContent = `${job.label}, seed ${job.seed}`;
    if (files.map) setSource(q("out-map"), files.map.url + "&inline=1");
    q("map-caption").textContent = job.metrics ? `source map (${job.metrics.map_source})` : "source map";
    const body = q("metrics").querySelector("tbody");
    body.replaceChildren();
    if (job.metrics) {
      for (const [name, value] of Object.entries(job.metrics.values)) {
        const row = element("tr");
        row.append(element("th", { title: job.metrics.descriptions[name] || "" }, name), element("td", {}, Number(value).toPrecision(4)));
        body.append(row);
      }
    }
  }
  if (isVideo) {
    const video = q("out-video");
    setSource(video, files.video.url + "&inline=1");
    video.play().catch(() => {});
  }
  if (isCompare) setSource(q("report"), files.report.url + "&inline=1");
  const list = q("downloads");
  list.replaceChildren();
  for (const [key, item] of Object.entries(files)) {
    const link = element("a", { href: item.url, download: item.name, "data-key": key }, item.name);
    const li = element("li");
    li.append(link);
    list.append(li);
  }
  q("command-line").textContent = job.command_line;
}

async function cancel() {
  if (!state.job) return;
  q("cancel").disabled = true;
  try {
    await api(`/api/jobs/${state.job.id}/cancel`, { method: "POST" });
  } catch (e) {
    showError(e.message);
  }
}

// ------------------------------------------------------------------ start
async function start() {
  let catalogue;
  try {
    catalogue = await api("/api/methods");
  } catch (e) {
    showError(e.message);
    return;
  }
  state.methods = catalogue.methods;
  state.limits = catalogue.limits;
  q("version").textContent = `version ${catalogue.version}`;
  q("upload-limits").textContent = `PNG, JPEG, TIFF, WebP or BMP, up to ${catalogue.limits.max_upload_bytes / 1e6} MB and ${catalogue.limits.max_pixels / 1e6} megapixels`;
  q("width").max = q("height").max = catalogue.limits.max_side;
  const select = q("method");
  const box = q("compare-methods");
  for (const m of state.methods) {
    select.append(element("option", { value: m.name }, m.name));
    const label = element("label", { title: m.summary });
    const check = element("input", { type: "checkbox", value: m.name });
    if (["quilting", "random_phase", "heeger_bergen"].includes(m.name)) check.checked = true;
    check.addEventListener("change", buildParams);
    label.append(check, document.createTextNode(" " + m.name));
    box.append(label);
  }
  select.value = "quilting";
  select.addEventListener("change", buildParams);
  document.querySelectorAll("#modes button").forEach((b) => b.addEventListener("click", () => setMode(b.dataset.mode)));
  q("new-seed").addEventListener("click", newSeed);
  q("run").addEventListener("click", run);
  q("cancel").addEventListener("click", cancel);
  q("file").addEventListener("change", (e) => { if (e.target.files.length) upload(e.target.files[0]); });
  const drop = q("drop");
  drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault();
    drop.classList.remove("over");
    if (e.dataTransfer.files.length) upload(e.dataTransfer.files[0]);
  });
  newSeed();
  setMode("synth");
  try {
    const builtins = await api("/api/exemplars/builtin");
    const row = q("builtins");
    for (const item of builtins.exemplars) {
      const button = element("button", { type: "button", "data-id": item.id, title: item.name });
      const img = element("img", { alt: item.name, src: withToken(`/api/exemplars/${encodeURIComponent(item.id)}/preview`) });
      button.append(img, document.createTextNode(item.name.replace("builtin:", "")));
      button.addEventListener("click", () => setExemplar(item));
      row.append(button);
    }
    if (!state.exemplar && builtins.exemplars.length) setExemplar(builtins.exemplars[0]);
  } catch (e) {
    showError(e.message);
  }
}

start();
