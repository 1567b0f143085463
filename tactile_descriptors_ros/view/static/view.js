// tactile view: the skin laid out by the robot description's geometry, coloured by force,
// the contact, each body part's vibration trace and the predictions.  Plain script: no
// build step, no library, no network beyond the server that sent it.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const view = { config: null, lut: [], parts: {}, frames: 0, seekable: false };
window.tactileView = view;  // for a console (and the tests): the last config and frame

function el(tag, attrs, parent) {
  const e = tag.startsWith("svg:") ? document.createElementNS(SVG, tag.slice(4)) : document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

function colour(force) {
  // the same map as the robot's markers and images: viridis over [0, force_max_n], grey when unknown
  if (force === null || force === undefined || !isFinite(force)) {
    const g = view.config.stale_rgb;
    return `rgb(${g[0]},${g[1]},${g[2]})`;
  }
  const i = Math.max(0, Math.min(255, Math.round(force / view.config.force_max_n * 255)));
  return view.lut[i];
}

function setup(config) {
  view.config = config;
  view.lut = [];
  for (let i = 0; i < 256; i++) {
    const h = config.colormap.substr(6 * i, 6);
    view.lut.push(`rgb(${parseInt(h.substr(0, 2), 16)},${parseInt(h.substr(2, 2), 16)},${parseInt(h.substr(4, 2), 16)})`);
  }
  document.getElementById("robot").textContent = config.robot || "tactile view";
  document.getElementById("source").textContent = config.source === "live" ? "live from the ROS graph" : `bag ${config.source}`;
  const notice = document.getElementById("notice");
  notice.hidden = !config.notice;
  notice.textContent = config.notice || "";
  document.getElementById("legend-max").textContent = `${config.force_max_n} N`;
  document.getElementById("legend-stale").textContent = `${config.stale_s}`;
  const ctx = document.getElementById("legend-scale").getContext("2d");
  for (let i = 0; i < 256; i++) { ctx.fillStyle = view.lut[i]; ctx.fillRect(i, 0, 1, 12); }
  const holder = document.getElementById("parts");
  holder.textContent = "";
  view.parts = {};
  for (const part of config.parts) {
    const sec = el("section", { class: "part", "data-part": part.name, "data-in-contact": "false" }, holder);
    const h = el("h3", {}, sec);
    el("span", { class: "name" }, h).textContent = part.name;
    const force = el("span", { class: "force" }, h);
    const xs = part.taxels.map(t => t.x), ys = part.taxels.map(t => t.y), r = part.radius;
    const x0 = Math.min(...xs) - 1.5 * r, x1 = Math.max(...xs) + 1.5 * r;
    const y0 = Math.min(...ys) - 1.5 * r, y1 = Math.max(...ys) + 1.5 * r;
    // y up on the layout, down on the screen
    const svg = el("svg:svg", { class: "cells", viewBox: `${x0} ${-y1} ${x1 - x0} ${y1 - y0}`,
                                preserveAspectRatio: "xMidYMid meet" }, sec);
    const circles = part.taxels.map(t => {
      const c = el("svg:circle", { cx: t.x, cy: -t.y, r: r, "data-taxel": t.name, "data-cell-id": t.cell_id,
                                   "data-force-n": "", "data-stale": "true", fill: colour(null) }, svg);
      el("svg:title", {}, c).textContent = t.name;
      return c;
    });
    const cop = el("svg:circle", { class: "cop", r: 0.9 * r, cx: 0, cy: 0, visibility: "hidden",
                                   "stroke-width": 0.25 * r }, svg);
    const cap = el("div", { class: "trace-caption" }, sec);
    const trace = el("svg:svg", { class: "trace", viewBox: "0 0 100 40", preserveAspectRatio: "none" }, sec);
    const line = el("svg:polyline", { fill: "none", stroke: "#5a7bd8", "stroke-width": "1",
                                      "vector-effect": "non-scaling-stroke", points: "" }, trace);
    view.parts[part.name] = { sec, force, circles, cop, line, cap, unit: part.vibration_unit };
  }
}

function update(frame) {
  view.frame = frame;
  view.frames += 1;
  // a bag shows its position on the progress bar; live, the sensors' clock as a time of day
  document.getElementById("clock").textContent = frame.t === null || frame.progress ? "" :
    new Date(frame.t * 1000).toLocaleTimeString();
  for (const p of frame.parts) {
    const v = view.parts[p.name];
    if (!v) continue;
    v.sec.dataset.inContact = p.in_contact ? "true" : "false";
    v.force.textContent = `${p.force_n.toFixed(2)} N`;
    p.force.forEach((f, i) => {
      const c = v.circles[i];
      c.setAttribute("fill", colour(f));
      c.dataset.forceN = f === null ? "" : String(f);  // the value the colour was made from, unrounded
      c.dataset.stale = f === null ? "true" : "false";
    });
    if (p.cop && view.config.geometry) {
      v.cop.setAttribute("cx", p.cop[0]);
      v.cop.setAttribute("cy", -p.cop[1]);
      v.cop.setAttribute("visibility", "visible");
    } else {
      v.cop.setAttribute("visibility", "hidden");
    }
    const tr = p.trace || [];
    v.cap.textContent = `vibration ${p.vibration_rms === null ? "-" : p.vibration_rms.toPrecision(3)} ${v.unit} rms`;
    if (tr.length > 1) {
      const t1 = tr[tr.length - 1][0], t0 = t1 - 10.0;
      const top = Math.max(...tr.map(q => q[1])) || 1;
      v.line.setAttribute("points", tr.map(q => `${((q[0] - t0) / 10.0 * 100).toFixed(2)},${(38 - q[1] / top * 36).toFixed(2)}`).join(" "));
    } else {
      v.line.setAttribute("points", "");
    }
  }
  const pred = frame.prediction;
  const box = document.getElementById("prediction");
  if (pred) {
    box.dataset.hasModel = pred.has_model ? "true" : "false";
    box.dataset.exploration = pred.exploration_id;
    document.getElementById("prediction-class").textContent = pred.has_model ? pred.class_name : "no model yet (label a touch)";
    document.getElementById("prediction-confidence").textContent = pred.has_model ? `confidence ${(100 * pred.confidence).toFixed(0)} %` : "";
    document.getElementById("prediction-bar").style.width = `${pred.has_model ? 100 * pred.confidence : 0}%`;
    document.getElementById("prediction-parts").textContent = pred.body_parts.length ? `touching: ${pred.body_parts.join(", ")}` : "";
  }
  const body = document.querySelector("#history tbody");
  body.textContent = "";
  for (const e of frame.history) {
    const tr = el("tr", { "data-exploration": e.exploration_id, "data-correct": e.correct === null ? "" : String(e.correct) }, body);
    el("td", {}, tr).textContent = e.exploration_id;
    el("td", {}, tr).textContent = e.has_model ? e.class_name : "-";
    el("td", {}, tr).textContent = e.has_model ? `${(100 * e.confidence).toFixed(0)} %` : "";
    el("td", {}, tr).textContent = e.label || "";
    el("td", {}, tr).textContent = e.correct === null ? "" : (e.correct ? "\u2713" : "\u2717");
  }
  const prog = document.getElementById("progress");
  if (frame.progress) {
    prog.hidden = false;
    const f = frame.progress.duration_s > 0 ? frame.progress.position_s / frame.progress.duration_s : 0;
    document.getElementById("progress-bar").style.width = `${(100 * Math.min(1, f)).toFixed(1)}%`;
    document.getElementById("progress-time").textContent =
      `${frame.progress.position_s.toFixed(1)} / ${frame.progress.duration_s.toFixed(1)} s${frame.progress.ended ? " (end)" : ""}`;
    prog.dataset.position = frame.progress.position_s.toFixed(3);
  }
}

function stats() {
  fetch("api/stats").then(r => r.json()).then(s => {
    document.getElementById("stats").textContent =
      `${s.clients.length} page(s) connected; frames published ${s.published}, dropped for slow pages ${s.dropped}`;
  }).catch(() => {});
}

document.getElementById("progress").addEventListener("click", ev => {
  const box = ev.currentTarget.getBoundingClientRect();
  const f = (ev.clientX - box.left) / box.width;
  const d = view.frame && view.frame.progress ? view.frame.progress.duration_s : 0;
  fetch(`api/seek?t=${(f * d).toFixed(3)}`);
});

function connect() {
  const status = document.getElementById("status");
  const es = new EventSource("events");
  es.addEventListener("config", ev => setup(JSON.parse(ev.data)));
  es.addEventListener("frame", ev => {
    if (!view.config) return;
    status.dataset.state = "live";
    status.textContent = "connected";
    update(JSON.parse(ev.data));
  });
  es.onerror = () => { status.dataset.state = "disconnected"; status.textContent = "reconnecting"; };
}

connect();
setInterval(stats, 2000);
