// The wise editor page: sends edits to the server one after another and shows the newest
// preview. Edits never wait for a render: while one runs, further edits queue and the page
// asks for a fresh preview once the render in flight has come back.
"use strict";

const $ = (id) => document.getElementById(id);
const editor = {
  server: null,        // the last state the server sent
  shown: -1,           // the state version of the full preview on screen
  quick: -1,           // the state version of the quick preview last shown
  rendering: false,
  pendingEdits: 0,
  queue: Promise.resolve(),
  painting: null,      // the points of the stroke being drawn
  param: null,         // the parameter the brush paints
};

async function api(path, options = {}) {
  const response = await fetch(path, options);
  if (!response.ok) {
    let detail = `${response.status} ${response.statusText}`;
    try { detail = (await response.json()).detail || detail; } catch (e) { /* not JSON */ }
    throw new Error(detail);
  }
  return response;
}

const postJSON = (path, body) => api(path, {
  method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body ?? {}),
}).then((r) => r.json());

function showError(error) {
  const message = $("message");
  message.textContent = error.message || String(error);
  message.hidden = false;
  setStatus();
}

function setStatus() {
  const status = $("status");
  const busy = editor.rendering || editor.pendingEdits > 0;
  status.dataset.state = busy ? "busy" : ($("message").hidden ? "ready" : "error");
  status.dataset.version = String(editor.shown);
  status.dataset.target = String(editor.server?.content ? editor.server.version : editor.shown);
  status.textContent = busy ? "rendering…" : ($("message").hidden ? "ready" : "error");
}

// Run an edit after the ones before it; its reply is the new state.
function edit(request) {
  editor.pendingEdits += 1;
  $("message").hidden = true;
  $("notice").hidden = true;
  setStatus();
  editor.queue = editor.queue
    .then(request)
    .then(applyState)
    .catch(showError)
    .finally(() => { editor.pendingEdits -= 1; refresh(); });
  return editor.queue;
}

// A new state is shown twice: at once as a quick, reduced preview, then in full. The full one
// is skipped while newer edits keep coming (their quick previews show them); it is drawn
// for the newest state once the edits have stopped.
async function refresh() {
  const state = editor.server;
  if (!state || !state.content || editor.rendering || state.version === editor.shown) { setStatus(); return; }
  editor.rendering = true;
  setStatus();
  try {
    if (state.version !== editor.quick) {
      const quick = await api("/api/preview?quick=1");
      const version = Number(quick.headers.get("X-Wise-Version"));
      const blob = await quick.blob();
      if (version > editor.shown) {
        await showImage($("preview"), blob);
        editor.quick = version;
        clearStroke();
      }
      if (editor.pendingEdits > 0 || editor.server.version !== version) return;  // newer edits: quick first
    }
    const response = await api("/api/preview");
    const version = Number(response.headers.get("X-Wise-Version"));
    await showImage($("preview"), await response.blob());
    editor.shown = version;
    editor.quick = version;
    clearStroke();
  } catch (error) {
    showError(error);
    editor.shown = state.version; // do not retry a failing render in a loop
  } finally {
    editor.rendering = false;
    // an edit in flight calls refresh when its reply comes
    if (editor.server.version !== editor.shown && editor.pendingEdits === 0) refresh(); else setStatus();
  }
}

function showImage(img, blob) {
  return new Promise((resolve) => {
    const old = img.src;
    img.onload = () => { if (old.startsWith("blob:")) URL.revokeObjectURL(old); resolve(); };
    img.src = URL.createObjectURL(blob);
  });
}

function formatValue(value) {
  return Math.abs(value) >= 100 ? value.toFixed(0) : Math.abs(value) >= 10 ? value.toFixed(1) : value.toFixed(2);
}

function applyState(state) {
  const previous = editor.server;
  editor.server = state;
  if (state.notice) {  // said once by the server, e.g. values of an opened file that were clamped
    $("notice").textContent = state.notice;
    $("notice").hidden = false;
  }
  const newEffect = !previous || previous.effect !== state.effect;
  if (newEffect) buildEffectControls(state);
  if (newEffect || !editor.param || !state.params.some((p) => p.name === editor.param)) {
    editor.param = state.params[0].name;
  }
  $("effect").value = state.effect;
  $("preset").value = state.preset ?? "";
  for (const p of state.params) {
    const row = document.querySelector(`.param[data-param="${p.name}"]`);
    const slider = row.querySelector("input[type=range]");
    if (document.activeElement !== slider || !slider.dataset.dragging) slider.value = p.mean;
    row.querySelector(".value").textContent = formatValue(p.mean);
    const local = row.querySelector(".local");
    local.hidden = p.high - p.low < 1e-6 * (p.max - p.min);
    local.textContent = `painted ${formatValue(p.low)} – ${formatValue(p.high)}`;
    row.classList.toggle("painting", p.name === editor.param);
    row.querySelector("input[type=radio]").checked = p.name === editor.param;
  }
  $("undo").disabled = !state.can_undo;
  $("redo").disabled = !state.can_redo;
  const hasContent = Boolean(state.content);
  $("empty").hidden = hasContent;
  $("views").hidden = !hasContent;
  $("export").disabled = !hasContent;
  if (hasContent && (!previous || !previous.content || previous.content.name !== state.content.name
      || previous.content.width !== state.content.width || previous.content.height !== state.content.height
      || previous.version > state.version)) {
    api("/api/content").then((r) => r.blob()).then((b) => showImage($("content"), b)).catch(showError);
  }
  // the quick preview is smaller than the full one: both are shown at the full one's size
  if (hasContent) $("preview").width = state.content.preview_width;
  updateMask();
  updateBrushValue(false);
}

function buildEffectControls(state) {
  const effectSelect = $("effect");
  effectSelect.replaceChildren(...Object.keys(state.effects).map((name) => new Option(name, name)));
  const presetSelect = $("preset");
  presetSelect.replaceChildren(new Option("(defaults)", ""),
    ...state.effects[state.effect].map((name) => new Option(name, name)));
  const list = $("params");
  list.replaceChildren();
  for (const p of state.params) {
    const row = document.createElement("div");
    row.className = "param";
    row.dataset.param = p.name;
    row.title = p.description;
    const step = (p.max - p.min) / 200;
    row.innerHTML = `
      <div class="head">
        <input type="radio" name="paint-param" id="pick-${p.name}" value="${p.name}">
        <label for="pick-${p.name}">${p.name}</label>
        <span class="value"></span>
        <button type="button" class="reset" title="Back to the opened values">reset</button>
      </div>
      <input type="range" min="${p.min}" max="${p.max}" step="${step}" aria-label="${p.name}">
      <div class="local" hidden></div>`;
    const slider = row.querySelector("input[type=range]");
    slider.addEventListener("input", () => {
      slider.dataset.dragging = "1";
      row.querySelector(".value").textContent = formatValue(Number(slider.value));
    });
    slider.addEventListener("change", () => {
      delete slider.dataset.dragging;
      edit(() => postJSON("/api/global", { param: p.name, value: Number(slider.value) }));
    });
    row.querySelector("input[type=radio]").addEventListener("change", () => selectParam(p.name));
    row.querySelector(".reset").addEventListener("click", () => edit(() => postJSON("/api/reset", { param: p.name })));
    list.append(row);
  }
}

function selectParam(name) {
  editor.param = name;
  for (const row of document.querySelectorAll(".param")) row.classList.toggle("painting", row.dataset.param === name);
  updateMask();
  updateBrushValue(true);
}

function currentParam() {
  return editor.server?.params.find((p) => p.name === editor.param);
}

function updateBrushValue(force) {
  const p = currentParam();
  const input = $("brush-value");
  if (!p) return;
  input.min = p.min; input.max = p.max; input.step = (p.max - p.min) / 100;
  if (force || input.value === "" || Number(input.value) < p.min || Number(input.value) > p.max) input.value = formatValue(p.mean);
}

function updateMask() {
  const mask = $("mask");
  const show = $("overlay").checked && editor.server?.content && editor.param;
  mask.hidden = !show;
  if (show) {
    const shown = `${editor.param}@${editor.server.version}`;
    api(`/api/mask/${encodeURIComponent(editor.param)}`).then((r) => r.blob())
      .then((b) => showImage(mask, b)).then(() => { mask.dataset.shown = shown; }).catch(showError);
  }
}

// ----- painting --------------------------------------------------------------------------

function brushMode() {
  return document.querySelector("input[name=brush-mode]:checked").value;
}

function showBrushMode() {
  const set = brushMode() === "set";
  $("brush-amount").disabled = set;
  $("brush-value").disabled = !set;
}

function pointerPosition(event) {
  const box = $("paint").getBoundingClientRect();
  return [(event.clientX - box.left) / box.width, (event.clientY - box.top) / box.height];
}

function brushRadius() {
  const box = $("paint").getBoundingClientRect();
  return Math.min(0.5, (Number($("brush-size").value) / 2) / Math.min(box.width, box.height));
}

function syncCanvas() {
  const canvas = $("paint");
  const box = canvas.getBoundingClientRect();
  if (canvas.width !== Math.round(box.width) || canvas.height !== Math.round(box.height)) {
    canvas.width = Math.round(box.width);
    canvas.height = Math.round(box.height);
  }
  return canvas;
}

function drawOverlay(cursor) {
  const canvas = syncCanvas();
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const radius = Number($("brush-size").value) / 2;
  if (editor.painting && editor.painting.length) {
    ctx.strokeStyle = "rgba(106, 167, 255, 0.45)";
    ctx.lineWidth = 2 * radius;
    ctx.lineCap = "round";
    ctx.lineJoin = "round";
    ctx.beginPath();
    editor.painting.forEach(([x, y], i) => (i ? ctx.lineTo : ctx.moveTo).call(ctx, x * canvas.width, y * canvas.height));
    if (editor.painting.length === 1) ctx.lineTo(editor.painting[0][0] * canvas.width + 0.01, editor.painting[0][1] * canvas.height);
    ctx.stroke();
  }
  if (cursor) {
    ctx.strokeStyle = "rgba(255, 255, 255, 0.9)";
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.arc(cursor[0] * canvas.width, cursor[1] * canvas.height, radius, 0, 2 * Math.PI);
    ctx.stroke();
  }
}

function clearStroke() {
  if (!editor.painting) drawOverlay(null);
}

function startStroke(event) {
  if (!editor.server?.content || !editor.param || event.button !== 0) return;
  $("paint").setPointerCapture(event.pointerId);
  editor.painting = [pointerPosition(event)];
  drawOverlay(editor.painting[0]);
}

function moveStroke(event) {
  const position = pointerPosition(event);
  if (editor.painting) editor.painting.push(position);
  drawOverlay(position);
}

function endStroke(event) {
  if (!editor.painting) return;
  const points = editor.painting;
  editor.painting = null;
  const mode = brushMode();
  const stroke = {
    param: editor.param,
    points: points.slice(0, 4096),
    radius: brushRadius(),
    hardness: Number($("brush-hardness").value) / 100,
    mode,
    amount: Number($("brush-amount").value) / 100,
  };
  if (mode === "set") stroke.value = Number($("brush-value").value);
  drawOverlay(pointerPosition(event));
  edit(() => postJSON("/api/stroke", stroke));
}

// ----- files -----------------------------------------------------------------------------

function upload(path, file) {
  edit(() => api(path, { method: "POST", body: file, headers: { "X-File-Name": file.name } }).then((r) => r.json()));
}

async function download(path) {
  editor.pendingEdits += 1;
  setStatus();
  try {
    await editor.queue;
    const response = await api(path);
    const disposition = response.headers.get("Content-Disposition") || "";
    const name = (disposition.match(/filename="([^"]+)"/) || [null, "download"])[1];
    const link = document.createElement("a");
    link.href = URL.createObjectURL(await response.blob());
    link.download = name;
    document.body.append(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(link.href), 60000);
  } catch (error) {
    showError(error);
  } finally {
    editor.pendingEdits -= 1;
    setStatus();
  }
}

function setView() {
  const view = $("view").value;
  $("views").className = view === "side" ? "side" : "";
  $("content-figure").hidden = view === "result";
  $("result-figure").hidden = view === "content";
}

function bindRange(id, unit) {
  const input = $(id);
  const show = () => { $(`${id}-value`).textContent = `${input.value} ${unit}`; };
  input.addEventListener("input", show);
  show();
}

function init() {
  // the access token is in a cookie now: keep it out of the address bar and the history
  if (new URLSearchParams(location.search).has("token")) history.replaceState(null, "", location.pathname);
  $("open-image").addEventListener("change", (e) => { if (e.target.files[0]) upload("/api/image", e.target.files[0]); e.target.value = ""; });
  $("open-params").addEventListener("change", (e) => { if (e.target.files[0]) upload("/api/params", e.target.files[0]); e.target.value = ""; });
  $("effect").addEventListener("change", () => edit(() => postJSON("/api/effect", { effect: $("effect").value })));
  $("preset").addEventListener("change", () => edit(() => postJSON("/api/effect", { effect: $("effect").value, preset: $("preset").value || null })));
  $("undo").addEventListener("click", () => edit(() => postJSON("/api/undo")));
  $("redo").addEventListener("click", () => edit(() => postJSON("/api/redo")));
  $("save").addEventListener("click", () => download("/api/params.safetensors"));
  $("export").addEventListener("click", () => download("/api/export.png"));
  $("view").addEventListener("change", setView);
  $("overlay").addEventListener("change", updateMask);
  const paint = $("paint");
  paint.addEventListener("pointerdown", startStroke);
  paint.addEventListener("pointermove", moveStroke);
  paint.addEventListener("pointerup", endStroke);
  paint.addEventListener("pointercancel", endStroke);
  paint.addEventListener("pointerleave", () => { if (!editor.painting) drawOverlay(null); });
  for (const radio of document.querySelectorAll("input[name=brush-mode]")) radio.addEventListener("change", showBrushMode);
  showBrushMode();
  bindRange("brush-size", "px");
  bindRange("brush-hardness", "%");
  bindRange("brush-amount", "%");
  document.addEventListener("keydown", (e) => {
    if (!(e.ctrlKey || e.metaKey) || e.target.tagName === "INPUT") return;
    const key = e.key.toLowerCase();
    if (key === "z" && !e.shiftKey && !$("undo").disabled) { e.preventDefault(); $("undo").click(); }
    if ((key === "y" || (key === "z" && e.shiftKey)) && !$("redo").disabled) { e.preventDefault(); $("redo").click(); }
  });
  setView();
  edit(() => api("/api/state").then((r) => r.json()));
}

document.addEventListener("DOMContentLoaded", init);
