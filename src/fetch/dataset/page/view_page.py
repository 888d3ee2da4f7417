"""The page `gym-fetch view` writes: one HTML file with its CSS and JS inline (no server, no network).

`{{SUMMARY}}` is replaced by the dataset's summary (JSON); each demo's series are loaded on demand
from `data/<demo>.js` (a script tag works from disk, where fetch() of a file is refused).
"""

from __future__ import annotations

import json
from typing import Any

_PAGE = r"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{{TITLE}}</title>
<style>
  body { font: 13px/1.4 system-ui, sans-serif; margin: 16px; color: #222; background: #fafafa; }
  h1 { font-size: 18px; margin: 0 0 4px; }
  h2 { font-size: 14px; margin: 12px 0 4px; }
  .sub { color: #666; margin-bottom: 12px; }
  #summary-plots, #plots { display: flex; flex-wrap: wrap; gap: 12px; }
  .card { background: #fff; border: 1px solid #ddd; border-radius: 4px; padding: 6px; }
  #layout { display: flex; gap: 16px; align-items: flex-start; }
  #table-wrap { max-height: 80vh; overflow-y: auto; flex: 0 0 auto; }
  table { border-collapse: collapse; background: #fff; }
  th, td { padding: 2px 8px; border-bottom: 1px solid #eee; text-align: right; white-space: nowrap; }
  th { position: sticky; top: 0; background: #f0f0f0; z-index: 1; }
  td.name, td.device, td.session { text-align: left; }
  tr.demo { cursor: pointer; }
  tr.demo:hover { background: #f3f7ff; }
  tr.selected { background: #dde8ff !important; }
  td.yes { color: #1a7f37; } td.no { color: #c62828; font-weight: bold; }
  video.thumb { width: 64px; height: 64px; display: block; background: #000; }
  #detail { flex: 1 1 auto; min-width: 400px; }
  #detail-video { width: 256px; height: 256px; background: #000; }
  svg text { font: 10px system-ui, sans-serif; fill: #444; }
  .problem { color: #c62828; }
  .flags, td.flags { color: #a15c00; }
</style>
</head>
<body>
<h1 id="title"></h1>
<div class="sub" id="subtitle"></div>
<ul id="file-problems" class="problem"></ul>
<div id="summary-plots"></div>
<div id="layout">
  <div id="table-wrap"><table id="demos"><thead><tr>
    <th>video</th><th>demo</th><th>length</th><th>seed</th><th>device</th><th>session</th><th>success</th><th>valid</th><th>flags</th>
  </tr></thead><tbody></tbody></table></div>
  <div id="detail">
    <h2 id="detail-title">select a demo</h2>
    <div id="detail-problem" class="problem"></div>
    <ul id="detail-flags" class="flags"></ul>
    <video id="detail-video" autoplay muted loop playsinline controls></video>
    <div id="plots"></div>
  </div>
</div>
<script id="summary" type="application/json">{{SUMMARY}}</script>
<script>
"use strict";
window.FetchView = (() => {
  const state = { selected: null, plotted: null, errors: [], cache: {} };
  window.addEventListener("error", (e) => state.errors.push(String(e.message)));
  const summary = JSON.parse(document.getElementById("summary").textContent);
  const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b"];
  const SVG = "http://www.w3.org/2000/svg";

  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
    for (const c of children) node.append(c);
    return node;
  }
  function svg(tag, attrs) {
    const node = document.createElementNS(SVG, tag);
    for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
    return node;
  }
  function text(x, y, s, anchor) {
    const t = svg("text", { x, y, "text-anchor": anchor || "start" });
    t.textContent = s;
    return t;
  }
  function fmt(v) {
    if (v === 0 || Math.abs(v) >= 100) return v.toFixed(0);
    return Math.abs(v) < 0.01 ? v.toExponential(1) : v.toPrecision(3);
  }

  // A line plot of several series over steps; labels name the series, in a row above the plot area
  // (not over the curves). `marks`: the demo's flags, drawn behind the lines: the steps of idle
  // stretches, chatter and lost successes shaded, each close of a regrasp a thin line, and the steps
  // a person drove after taking over from a policy shaded blue.
  function linePlot(title, series, labels, marks) {
    const W = 280, H = 142, L = 48, R = 6, T = 28, B = 18;
    const root = svg("svg", { width: W, height: H, class: "plot", "data-title": title });
    let lo = Infinity, hi = -Infinity, n = 0;
    for (const s of series) {
      n = Math.max(n, s.length);
      for (const v of s) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    }
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-9) { lo -= 0.5; hi += 0.5; }
    const x = (i) => L + (W - L - R) * (n > 1 ? i / (n - 1) : 0.5);
    const y = (v) => T + (H - T - B) * (1 - (v - lo) / (hi - lo));
    root.append(svg("rect", { x: L, y: T, width: W - L - R, height: H - T - B, fill: "#fff", stroke: "#ccc" }));
    for (const f of marks || []) {
      if (f.kind === "long") continue;  // the whole demo: said in its row
      for (const [a, b] of f.where) {
        const close = f.kind === "regrasp", person = f.kind === "takeover";
        root.append(svg("rect", { x: x(a), y: T, width: close ? 1.5 : Math.max(1, x(b - 1) - x(a)),
                                  height: H - T - B, fill: close ? "#a15c00" : person ? "#cfe3ff" : "#ffe0b2",
                                  class: person ? "takeover" : "flagged" }));
      }
    }
    root.append(text(4, 11, title));
    root.append(text(L - 3, T + 8, fmt(hi), "end"), text(L - 3, H - B, fmt(lo), "end"));
    root.append(text(L, H - 4, "step 0"), text(W - R, H - 4, String(n - 1), "end"));
    let legendX = L + 4;
    series.forEach((s, k) => {
      const points = s.map((v, i) => v === null ? "" : x(i).toFixed(1) + "," + y(v).toFixed(1)).join(" ");
      root.append(svg("polyline", { points, fill: "none", stroke: COLORS[k % COLORS.length], "stroke-width": 1.3 }));
      if (labels && labels[k]) {
        const t = text(legendX, T - 5, labels[k]);
        legendX += 7 * labels[k].length + 10;
        t.setAttribute("style", "fill:" + COLORS[k % COLORS.length]);
        t.setAttribute("class", "legend");
        root.append(t);
      }
    });
    return el("div", { class: "card" }, root);
  }

  // Bars with a label under each and a text above it.
  function barChart(title, bars) {
    const W = Math.max(200, 34 * bars.length + 50), H = 140, L = 10, T = 30, B = 30;
    const root = svg("svg", { width: W, height: H, class: "bars", "data-title": title });
    root.append(text(4, 11, title));
    const top = Math.max(1e-9, ...bars.map((b) => b.value));
    const w = (W - 2 * L) / Math.max(1, bars.length);
    bars.forEach((b, i) => {
      const h = (H - T - B) * b.value / top;
      root.append(svg("rect", { x: L + i * w + 2, y: H - B - h, width: w - 4, height: h, fill: COLORS[0] }));
      root.append(text(L + i * w + w / 2, H - B - h - 2, b.text, "middle"));
      root.append(text(L + i * w + w / 2, H - B + 12, b.label.slice(0, 12), "middle"));
    });
    return el("div", { class: "card" }, root);
  }

  function lengthHistogram(lengths) {
    if (!lengths.length) return barChart("episode length", []);
    const lo = Math.min(...lengths), hi = Math.max(...lengths);
    const bins = Math.min(12, hi - lo + 1), width = (hi - lo + 1) / bins;
    const counts = new Array(bins).fill(0);
    for (const v of lengths) counts[Math.min(bins - 1, Math.floor((v - lo) / width))] += 1;
    return barChart("episode length (steps)", counts.map((c, i) => ({
      value: c, text: String(c), label: String(Math.round(lo + i * width)) })));
  }

  function successBy(key, title) {
    const groups = {};
    for (const d of summary.demos) {
      const g = (groups[d[key]] = groups[d[key]] || { n: 0, ok: 0 });
      g.n += 1; g.ok += d.success ? 1 : 0;
    }
    return barChart(title, Object.entries(groups).map(([k, g]) => ({
      label: k, value: g.ok / g.n, text: Math.round(100 * g.ok / g.n) + "% of " + g.n })));
  }

  // Thumbnails load and play only while their row is on screen (a dataset may hold thousands).
  const watcher = new IntersectionObserver((entries) => {
    for (const e of entries) {
      const v = e.target;
      if (e.isIntersecting) {
        if (!v.getAttribute("src")) v.setAttribute("src", v.dataset.src);
        v.play().catch(() => {});
      } else {
        v.pause();
      }
    }
  });

  function cell(value, cls) { return el("td", cls ? { class: cls } : {}, String(value)); }
  function flag(ok, title) {
    const td = el("td", { class: ok ? "yes" : "no" }, ok ? "\u2713" : "\u2717");
    if (title) td.title = title;
    return td;
  }

  // What the demo holds that is known to hurt learning (fetch.dataset.habits): kinds in the row, texts in its title.
  function flagsCell(flags) {
    const td = el("td", { class: "flags" }, flags.map((f) => f.kind).join(", "));
    td.title = flags.map((f) => f.text).join("\n");
    return td;
  }

  function buildTable() {
    const body = document.querySelector("#demos tbody");
    for (const d of summary.demos) {
      const video = el("video", { class: "thumb", muted: "", loop: "", playsinline: "", autoplay: "" });
      video.muted = true;
      if (d.video) { video.dataset.src = d.video; watcher.observe(video); }
      const row = el("tr", { class: "demo", id: "row-" + d.name, "data-demo": d.name },
        el("td", {}, video), cell(d.name, "name"), cell(d.length), cell(d.seed), cell(d.device, "device"),
        cell(d.session, "session"), flag(d.success), flag(d.valid, d.problem), flagsCell(d.flags));
      row.addEventListener("click", () => select(d.name));
      body.append(row);
    }
  }

  function select(name) {
    const d = summary.demos.find((x) => x.name === name);
    if (!d) throw new Error("no demo " + name);
    state.selected = name;
    document.querySelectorAll("tr.selected").forEach((r) => r.classList.remove("selected"));
    document.getElementById("row-" + name).classList.add("selected");
    document.getElementById("detail-title").textContent = name + ": " + d.length + " steps, seed " + d.seed +
      ", " + d.device + (d.success ? ", successful" : ", failed");
    document.getElementById("detail-problem").textContent = d.problem || "";
    document.getElementById("detail-flags").replaceChildren(...d.flags.map((f) =>
      el("li", { title: summary.flag_kinds[f.kind] }, f.text)));
    const video = document.getElementById("detail-video");
    if (d.video) { video.src = d.video; video.play().catch(() => {}); } else { video.removeAttribute("src"); }
    if (state.cache[name]) { draw(name); return; }
    document.getElementById("plots").replaceChildren(el("div", {}, d.data ? "loading..." : "no readable data"));
    if (d.data) document.body.append(el("script", { src: d.data }));
  }

  function receive(name, data) {
    state.cache[name] = data;
    if (state.selected === name) draw(name);
  }

  function draw(name) {
    const data = state.cache[name];
    const flags = summary.demos.find((x) => x.name === name).flags;
    const marks = data.takeovers && data.takeovers.length ? flags.concat([{ kind: "takeover", where: data.takeovers }])
                                                          : flags;
    const plots = [linePlot("action", data.actions, ["x", "y", "z", "grip"], marks),
                   linePlot("reward, is_success", [data.reward, data.success], ["reward", "success"])];
    for (const [part, values] of Object.entries(data.obs)) {
      const labels = values.length === 3 ? ["x", "y", "z"] : values.length > 1 ? values.map((_, i) => String(i)) : null;
      plots.push(linePlot(part, values, labels));
    }
    document.getElementById("plots").replaceChildren(...plots);
    state.plotted = name;
    document.body.dataset.plotted = name;
  }

  document.getElementById("title").textContent = summary.env_id + ": " + summary.demos.length + " demos";
  document.getElementById("subtitle").textContent = summary.path + " \u2014 camera " + summary.camera +
    ", " + summary.fps + " fps; click a row for its plots";
  document.getElementById("file-problems").append(...(summary.problems || []).map((p) => el("li", {}, p)));
  document.getElementById("summary-plots").append(lengthHistogram(summary.demos.map((d) => d.length)),
    successBy("device", "success by device"), successBy("session", "success by session"));
  buildTable();
  if (summary.demos.length) select(summary.demos[0].name);
  return { select, receive, state, summary };
})();
</script>
</body>
</html>
"""


def page(summary: dict[str, Any], title: str) -> str:
    """The HTML page for `summary` (JSON-able). Every string of a dataset (its path, attributes, demo names)
    is data to the page, never markup: the inline JSON holds no `<`, `>` or `&` (escaped as `\\u003c`...),
    so no `</script>` ends its tag early and no `<!--<script` swallows the page's script; the page puts
    strings in with `textContent` only; the title is HTML-escaped."""
    data = json.dumps(summary, separators=(",", ":")).replace("<", "\\u003c").replace(">", "\\u003e") \
        .replace("&", "\\u0026")
    safe_title = title.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return _PAGE.replace("{{TITLE}}", safe_title).replace("{{SUMMARY}}", data)


def data_script(name: str, series: dict[str, Any]) -> str:
    """The body of `data/<name>.js`: it hands the demo's series to the page."""
    return f"window.FetchView.receive({json.dumps(name)}, {json.dumps(series, separators=(',', ':'))});\n"
