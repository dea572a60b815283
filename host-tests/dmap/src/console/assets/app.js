// dmap console: the page. Plain JavaScript, no build step: one event
// stream (/api/events) keeps the state; requests go to /api/request.
"use strict";

const TOKEN = new URLSearchParams(location.search).get("token") || "";
const BOX = "#ff00ff"; // the objects' boxes: a colour the scale never takes
const MARGIN = { left: 52, top: 10, right: 78, bottom: 40 };
const parts = { current: null, last: null };
window.consoleGeometry = {};
window.consoleState = null;

// A perceptual scale (viridis, by its control points).
const STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
function colour(t) {
  if (!(t >= 0)) t = 0;
  if (t > 1) t = 1;
  const x = t * (STOPS.length - 1), i = Math.min(Math.floor(x), STOPS.length - 2), f = x - i;
  const a = STOPS[i], b = STOPS[i + 1];
  return `rgb(${a.map((v, k) => Math.round(v + (b[k] - v) * f)).join(",")})`;
}

const $ = (id) => document.getElementById(id);
function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = text;
  if (cls) e.className = cls;
  return e;
}
const fmt = (v, d = 2) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));

// Keeps a part's map: rows arrive in pieces ("map": from, values, fired).
function merge(which, p) {
  if (!p) { parts[which] = null; return; }
  let k = parts[which];
  if (!k || k.n !== p.n) {
    k = { n: p.n, values: new Array(p.rows * p.cols).fill(null), fired: new Array(p.rows * p.cols).fill(0) };
  }
  Object.assign(k, p, { values: k.values, fired: k.fired });
  if (p.map) {
    const at = p.map.from * p.cols;
    p.map.values.forEach((v, i) => { k.values[at + i] = v; });
    p.map.fired.forEach((v, i) => { k.fired[at + i] = v; });
  }
  parts[which] = k;
}

function niceStep(span, n) {
  const raw = span / n, p = Math.pow(10, Math.floor(Math.log10(raw))), m = raw / p;
  return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
}

function draw(which, pitchUm) {
  const c = $(which + "-map"), g = c.getContext("2d"), p = parts[which];
  g.clearRect(0, 0, c.width, c.height);
  if (!p || !p.has_map) {
    g.fillStyle = "#777"; g.font = "14px sans-serif";
    g.fillText(p ? "scan too large to draw" : "waiting for a part", 20, 30);
    return;
  }
  const w = c.width - MARGIN.left - MARGIN.right, h = c.height - MARGIN.top - MARGIN.bottom;
  const cell = Math.max(1, Math.floor(Math.min(w / p.cols, h / p.rows)));
  const x0 = MARGIN.left, y0 = MARGIN.top;
  window.consoleGeometry[which] = { x0, y0, cell, rows: p.rows, cols: p.cols, n: p.n };
  let vmax = 2 * (p.threshold || 0);
  for (const v of p.values) if (v !== null && v > vmax) vmax = v;
  if (!(vmax > 0)) vmax = 1;
  for (let r = 0; r < p.rows; r++) {
    for (let q = 0; q < p.cols; q++) {
      const v = p.values[r * p.cols + q];
      g.fillStyle = v === null ? (r < p.rows_seen ? "#3a3f4b" : "#e8eaee") : colour(v / vmax);
      g.fillRect(x0 + q * cell, y0 + r * cell, cell, cell);
    }
  }
  // Axes: millimetres when the pitch is known, else positions.
  const unit = pitchUm ? pitchUm / 1000 : 1, label = pitchUm ? "mm" : "positions";
  g.fillStyle = "#1d2330"; g.strokeStyle = "#1d2330"; g.font = "11px sans-serif";
  const ticks = (n, horiz) => {
    const step = niceStep(n * unit, 5);
    for (let t = 0; t <= n * unit + 1e-9; t += step) {
      const px = (t / unit) * cell;
      const s = Number(t.toFixed(3)).toString();
      if (horiz) { g.fillRect(x0 + px, y0 + p.rows * cell, 1, 4); g.fillText(s, x0 + px - 6, y0 + p.rows * cell + 15); }
      else { g.fillRect(x0 - 4, y0 + px, 4, 1); g.fillText(s, x0 - 34, y0 + px + 4); }
    }
  };
  ticks(p.cols, true); ticks(p.rows, false);
  g.fillText(label, x0 + (p.cols * cell) / 2 - 10, y0 + p.rows * cell + 32);
  // The scale, with the threshold marked.
  const bx = x0 + p.cols * cell + 14, bh = p.rows * cell;
  for (let i = 0; i < bh; i++) { g.fillStyle = colour(1 - i / bh); g.fillRect(bx, y0 + i, 14, 1); }
  g.fillStyle = "#1d2330";
  g.fillText(fmt(vmax, 2), bx + 18, y0 + 8); g.fillText("0", bx + 18, y0 + bh);
  if (p.threshold > 0 && p.threshold <= vmax) {
    const ty = y0 + bh * (1 - p.threshold / vmax);
    g.fillRect(bx - 3, ty, 20, 1); g.fillText("thr", bx + 18, ty + 4);
  }
  // Each object's box and id, with the channels that fired.
  g.strokeStyle = BOX; g.lineWidth = 2; g.fillStyle = BOX; g.font = "bold 12px sans-serif";
  for (const o of p.objects) {
    const x = x0 + o.cols[0] * cell, y = y0 + o.rows[0] * cell;
    const bw = (o.cols[1] - o.cols[0] + 1) * cell, bhh = (o.rows[1] - o.rows[0] + 1) * cell;
    g.strokeRect(x + 1, y + 1, bw - 2, bhh - 2);
    g.fillText(`${o.id} ${o.channels.join("+")}`, x + 2, y > 14 ? y - 3 : y + bhh + 12);
  }
}

function objectsTable(which, p, pitchUm) {
  const t = $(which + "-objects");
  t.tHead.replaceChildren();
  const head = el("tr");
  const sizeHead = pitchUm ? "size (mm)" : "size (positions)";
  ["id", "rows", "cols", sizeHead, "peak (× thr)", "channels", "centroid (row, col)"].forEach((s) => head.append(el("th", s)));
  t.tHead.append(head);
  const body = t.tBodies[0];
  body.replaceChildren();
  for (const o of (p && p.objects) || []) {
    const tr = el("tr");
    tr.dataset.id = o.id;
    tr.dataset.box = [o.rows[0], o.rows[1], o.cols[0], o.cols[1]].join(",");
    const size = o.size_mm ? `${fmt(o.size_mm[0])} × ${fmt(o.size_mm[1])}` : `${o.size[0]} × ${o.size[1]}`;
    [o.id, `${o.rows[0]}–${o.rows[1]}`, `${o.cols[0]}–${o.cols[1]}`, size, fmt(o.peak),
      o.channels.join(", "), `${fmt(o.centroid[0])}, ${fmt(o.centroid[1])}`].forEach((s) => tr.append(el("td", String(s))));
    body.append(tr);
  }
}

function verdictClass(v) {
  if (!v) return "";
  if (v === "good" || v === "obj" || v === "damaged") return v;
  return "fault";
}

function kv(table, rows) {
  table.replaceChildren();
  for (const [k, v] of rows) {
    const tr = el("tr"); tr.dataset.key = k;
    tr.append(el("td", k), el("td", v === null || v === undefined ? "–" : String(v)));
    table.append(tr);
  }
}

function outputs(s) {
  const o = s.outputs, ready = $("ready"), reject = $("reject"), v = s.last ? s.last.verdict : null;
  ready.className = "lamp ready " + (!o ? "off" : !o.trusted ? "unknown" : o.ready ? "on" : "off");
  reject.className = "lamp reject " + (!o ? "off" : !o.trusted ? "unknown" : o.reject ? "on" : "off");
  reject.textContent = !o ? "REJECT" : !o.trusted ? "REJECT ?" : o.reject ? "REJECT asserted" : "REJECT released";
  ready.textContent = !o ? "READY" : !o.trusted ? "READY ?" : o.ready ? "READY" : "NOT READY";
  const verdict = $("verdict");
  verdict.textContent = v || "no part yet";
  verdict.className = "verdict " + verdictClass(v);
  verdict.dataset.verdict = v || "";
}

let settingsBuilt = false;
function settings(s) {
  const body = $("settings").tBodies[0];
  if (!settingsBuilt && s.settings.length) {
    for (const k of s.settings) {
      const tr = el("tr"); tr.dataset.key = k.key;
      const input = el("input"); input.className = "value-input"; input.placeholder = k.key;
      const btn = el("button", "set"); btn.type = "button"; btn.className = "set";
      btn.onclick = () => send(`set ${k.key}=${input.value.trim()}`, tr.querySelector(".outcome"), btn);
      input.onkeydown = (e) => { if (e.key === "Enter") btn.click(); };
      const tdIn = el("td"); tdIn.append(input);
      const tdBtn = el("td"); tdBtn.append(btn);
      tr.append(el("td", k.key), el("td", "", "value"), el("td", "", "range"), el("td", "", "source"),
        el("td", "", "scan-source"), tdIn, tdBtn, el("td", "", "outcome"));
      body.append(tr);
    }
    settingsBuilt = true;
  }
  for (const k of s.settings) {
    const tr = body.querySelector(`tr[data-key="${k.key}"]`);
    if (!tr) continue;
    tr.querySelector(".value").textContent = k.value === null ? "?" : k.value;
    tr.querySelector(".range").textContent = k.number ? `${k.range[0]} .. ${k.range[1]}` : k.range.join(" | ");
    tr.querySelector(".source").textContent = k.source ? `${k.source.letter} (${k.source.text})` : "?";
    tr.querySelector(".scan-source").textContent = k.scan_source || "–";
  }
  const st = s.status;
  $("sensor").textContent = st ? `firmware ${st.firmware}, detector ${st.detector}, capacity ${st.capacity}, store ${st.store}, started by ${st.reset_cause} (${st.boots})` : (s.requests ? "" : "this source takes no requests: read-only");
  const c = s.calibration;
  $("calibration").textContent = !c ? "" : c.result
    ? `calibrated on ${c.result.scans} scans (${c.result.positions} positions): thr ${c.result.thr}, pthr ${c.result.pthr}, sthr ${c.result.sthr} (in effect from the next scan, not saved)`
    : c.refused ? `calibration ended without a result: ${c.refused}` : `calibrating: ${c.done} of ${c.scans} scans`;
}

async function send(words, where, button) {
  if (button) button.disabled = true;
  if (where) { where.textContent = "…"; where.className = where.className.replace(/ ?(refusal|ok)/g, ""); }
  try {
    const r = await fetch("/api/request", {
      method: "POST",
      headers: { "Content-Type": "application/json", "X-Console-Token": TOKEN },
      body: JSON.stringify({ request: words }),
    });
    const j = await r.json();
    if (where) {
      where.textContent = j.ok ? "done" : j.error;
      where.classList.add(j.ok ? "ok" : "refusal");
    }
  } catch (e) {
    if (where) { where.textContent = `no answer: ${e}`; where.classList.add("refusal"); }
  } finally {
    if (button) button.disabled = false;
  }
}

function render(s) {
  window.consoleState = s;
  merge("current", s.current);
  merge("last", s.last);
  $("source").textContent = s.source;
  const cur = parts.current, last = parts.last;
  $("current-n").textContent = cur ? `#${cur.n}` : "";
  $("current-rows").textContent = cur ? `${cur.rows_seen} of ${cur.rows} rows` : "";
  $("last-n").textContent = last ? `#${last.n}` : "";
  const lv = $("last-verdict");
  lv.textContent = last ? last.verdict : ""; lv.className = "verdict small " + verdictClass(last && last.verdict);
  draw("current", s.pitch_um); draw("last", s.pitch_um);
  objectsTable("current", cur, s.pitch_um); objectsTable("last", last, s.pitch_um);
  outputs(s);
  const c = s.counters;
  kv($("counters"), [["parts", c.parts], ["rejects", c.rejects], ["faults", c.faults], ["damaged", c.damaged],
    ["line errors", c.line_errors], ["missing positions", c.missing], ["lines", c.lines]]);
  const hb = $("history").tBodies[0];
  hb.replaceChildren();
  for (const h of s.history) {
    const tr = el("tr");
    tr.append(el("td", `#${h.n}`), el("td", h.verdict, "verdict-cell " + verdictClass(h.verdict)),
      el("td", String(h.objects)), el("td", new Date(h.ended_ms).toLocaleTimeString()));
    hb.append(tr);
  }
  settings(s);
  const hl = s.health;
  kv($("health"), [["protocol version", hl.protocol], ["firmware header", hl.header_line],
    ["line errors", c.line_errors], ["command replies", c.replies], ["source", hl.source_end || "live"]]);
  kv($("kinds"), Object.entries(hl.kinds));
  const ul = $("recent");
  ul.replaceChildren();
  for (const e of hl.recent.slice().reverse()) ul.append(el("li", `line ${e.line} (${e.kind}): ${e.what}`));
  if (s.last_request && !s.last_request.ok && s.last_request.words.startsWith("set ")) {
    const key = s.last_request.words.slice(4).split("=")[0];
    const out = document.querySelector(`#settings tr[data-key="${key}"] .outcome`);
    if (out && out.textContent === "…") { out.textContent = s.last_request.reason; out.classList.add("refusal"); }
  }
}

function connect() {
  const es = new EventSource("/api/events");
  es.addEventListener("state", (e) => { $("link").textContent = "live"; $("link").className = "pill live"; render(JSON.parse(e.data)); });
  es.onerror = () => { $("link").textContent = "reconnecting"; $("link").className = "pill"; };
}

$("save").onclick = () => send("save", $("action-result"), $("save"));
$("defaults").onclick = () => send("defaults", $("action-result"), $("defaults"));
$("reset").onclick = () => send("reset", $("action-result"), $("reset"));
$("calibrate").onclick = () => send(`calibrate --scans ${$("cal-n").value}`, $("action-result"), $("calibrate"));
$("png").onclick = () => {
  $("last-map").toBlob((b) => {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(b);
    a.download = `part-${parts.last ? parts.last.n : 0}.png`;
    a.click();
  }, "image/png");
};
connect();
