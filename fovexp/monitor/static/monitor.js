// fovexp monitor: renders the server's events (/api/stream) into the page. Read-only: nothing
// here sends anything but GET requests. Text from the results folder is always set as text
// (textContent), never parsed as HTML.
"use strict";

const params = new URLSearchParams(location.search);
const token = params.get("token");
let key = params.get("key");
let source = null;
let lastEvent = 0;
let lastData = null;
const RULE_LABEL = {
  "R11 blanking": "blanked share",
  "R12 dropped frames": "dropped frames",
  "R13 latency": "gaze-to-flip p95",
};

const $ = (id) => document.getElementById(id);

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else if (k === "style") e.style.cssText = v;  // CSSOM: allowed by the page's CSP
    else e.setAttribute(k, v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

function pct(v, digits = 1) {
  return v === null || v === undefined ? "–" : (100 * v).toFixed(digits) + " %";
}
function ms(v) { return v === null || v === undefined ? "–" : v.toFixed(1) + " ms"; }
function num(v, digits = 3) {
  return v === null || v === undefined ? "–" : Number(v).toPrecision(digits).replace(/\.?0+$/, "");
}
function duration(s) {
  if (s === null || s === undefined || !isFinite(s)) return "?";
  s = Math.round(s);
  return s >= 60 ? `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, "0")} s` : `${s} s`;
}
function ago(serverTime, t) {
  if (!t) return "";
  const d = Math.max(0, serverTime - t);
  return d < 1.5 ? "just now" : `${duration(d)} ago`;
}

// how and when a finished session ended (the view's "end"), in one phrase
function ending(end, serverTime) {
  if (!end) return "";
  let text = end.how || end.state || "ended";
  if (end.at) {
    text += ` at ${end.at}`;
    if (end.time && serverTime - end.time < 3600) text += ` (${ago(serverTime, end.time)})`;
  }
  return text;
}

function setConn(text, cls) {
  const c = $("conn");
  c.textContent = text;
  c.className = "conn " + cls;
}

function streamUrl() {
  const q = new URLSearchParams();
  if (key) q.set("key", key);
  if (token) q.set("token", token);
  return "/api/stream?" + q.toString();
}

function connect() {
  if (source) source.close();
  source = new EventSource(streamUrl());
  source.onmessage = (e) => {
    lastEvent = Date.now();
    // events received (tests and benchmarks/display_loop.py read it)
    document.documentElement.dataset.events = String(1 + Number(
      document.documentElement.dataset.events || 0));
    let data;
    try { data = JSON.parse(e.data); } catch (err) { return; }
    setConn("live", "ok");
    try { render(data); } catch (err) { console.error(err); }
  };
  source.onerror = () => setConn("server unreachable: retrying…", "bad");
}

function select(k) {
  key = k;
  const q = new URLSearchParams(location.search);
  q.set("key", k);
  history.replaceState(null, "", "?" + q.toString());
  connect();
}

setInterval(() => {
  if (lastEvent && Date.now() - lastEvent > 5000) {
    setConn(`no data from the server for ${Math.round((Date.now() - lastEvent) / 1000)} s`,
            "bad");
  }
}, 1000);

function sessionItem(s, data, selected) {
  const state = s.status === "running" ? (s.state || "") :
                s.status === "stopped" ? "not responding" :
                (s.end && s.end.how) || s.file_state || s.state || "";
  let sub = state;
  if (s.position && s.total) {
    sub = (state === "trial" ? "" : state + " · ") +
          `${s.practice ? "practice " : ""}trial ${s.position}/${s.total}`;
  }
  else if (s.n_completed !== null && s.n_trials) sub += ` · ${s.n_completed}/${s.n_trials} trials`;
  if (s.status !== "finished" && s.flagged && s.flagged.length) sub += " · flagged";
  const li = el("li", {class: selected ? "sel" : "", "data-key": s.key},
                el("span", {text: `${s.experiment} / ${s.participant}`}),
                el("span", {class: "sub", text: `${s.session} · ${sub}`}));
  li.addEventListener("click", () => select(s.key));
  if (s.status === "finished" && data.report) {
    const a = el("a", {href: data.report + (token ? "?token=" + encodeURIComponent(token) : ""),
                       target: "_blank", rel: "noopener", class: "report-link", text: "report"});
    a.addEventListener("click", (e) => e.stopPropagation());
    li.firstChild.after(" ", a);
  }
  return li;
}

function renderLists(data) {
  const view = data.view;
  const running = data.sessions.filter((s) => s.status !== "finished");
  const finished = data.sessions.filter((s) => s.status === "finished");
  for (const [id, items] of [["running", running], ["finished", finished]]) {
    const ul = $(id);
    ul.replaceChildren(...(items.length ? items.map((s) =>
      sessionItem(s, data, view && view.key === s.key)) : [el("li", {class: "none", text: "none"})]));
  }
  $("root").textContent = data.root;
}

function renderGaze(view) {
  const g = view.gaze;
  const trail = $("trail"), now = $("now");
  const r = view.radius_deg || 1.25;
  $("window").setAttribute("r", r);
  if (!g || !g.t.length) {
    trail.setAttribute("d", "");
    now.setAttribute("visibility", "hidden");
    $("gaze-info").textContent = view.status === "running" ? "no gaze samples yet" :
      "no gaze samples " + (view.status === "finished" ? "at the end" : "when it stopped");
    $("gaze").dataset.newest = "";
    return;
  }
  $("gaze-window").textContent = g.window_s || 3;
  const L = 3.0;
  const clamp = (v) => Math.max(-L, Math.min(L, v));
  let d = "", pen = false, invalid = 0, last = null;
  for (let i = 0; i < g.t.length; i++) {
    const x = g.x_deg[i], y = g.y_deg[i];
    if (x === null || y === null) { pen = false; invalid++; continue; }
    d += (pen ? "L" : "M") + clamp(x).toFixed(3) + " " + clamp(y).toFixed(3);
    pen = true;
    last = [x, y];
  }
  trail.setAttribute("d", d);
  const svg = $("gaze");
  svg.dataset.newest = String(g.t.length) + ":" + (last ? last.join(",") : "none");
  svg.dataset.points = String(g.t.length);
  const newestValid = g.x_deg[g.x_deg.length - 1] !== null;
  if (last && newestValid) {
    const ecc = Math.hypot(last[0], last[1]);
    now.setAttribute("cx", clamp(last[0]).toFixed(3));
    now.setAttribute("cy", clamp(last[1]).toFixed(3));
    now.setAttribute("visibility", "visible");
    now.setAttribute("class", "now" + (ecc > r ? " outside" : "") +
                     (Math.abs(last[0]) > L || Math.abs(last[1]) > L ? " edge" : ""));
  } else {
    now.setAttribute("visibility", "hidden");
  }
  const parts = [];
  const t = view.trial;
  if (view.status === "running" && view.state === "trial" && t) {
    parts.push(t.blank ? "screen BLACK (gaze check)" : "stimulus shown");
    if (t.gaze_ecc_deg !== null) parts.push(`gaze ${t.gaze_ecc_deg.toFixed(2)}° from the cross`);
  }
  if (view.status !== "running") {
    // the view sends no rates for a run that is not running: the trail is its last seconds
    parts.push(view.status === "finished" ? "the last seconds before the end" :
               "the last seconds it wrote");
  }
  if (g.samples_last_s !== null) parts.push(`${g.samples_last_s} samples in the last second`);
  if (invalid) parts.push(`${invalid} without an eye (shown as gaps)`);
  if (g.newest_age_s !== null && g.newest_age_s > 1) {
    parts.push(`newest sample ${duration(g.newest_age_s)} old`);
  }
  $("gaze-info").textContent = parts.join(" · ");
}

function ruleRow(rule, r, t) {
  const limit = r.limit;
  let value;
  if (rule === "R13 latency") {
    value = r.value === null ? "no gaze sample yet" :
      `${ms(r.value)} (median ${ms(t && t.latency_ms ? t.latency_ms.median : null)})`;
  } else if (rule === "R12 dropped frames") {
    value = t && t.frames ? `${t.dropped} of ${t.frames} frames (${pct(r.value)})` : pct(r.value);
  } else {
    value = pct(r.value);
  }
  // the bar: the limit at its middle
  const frac = r.value === null ? 0 : r.value / (2 * limit);
  const lim = r.unit === "ms" ? `${limit} ms` : pct(limit, 0);
  const bar = el("div", {class: "bar"},
                 el("span", {style: `width: ${Math.min(100, 100 * frac).toFixed(1)}%`}),
                 el("i", {style: "left: 50%"}));
  const flag = r.exceeded ? el("span", {class: "flag", "data-rule": rule,
                                        text: `${rule.split(" ")[0]}: would be excluded`})
                          : el("span", {class: "okmark", text: "within"});
  return el("div", {class: "rule" + (r.exceeded ? " over" : ""), "data-rule": rule},
            el("div", {class: "rule-head"},
               el("b", {text: `${rule.split(" ")[0]} ${RULE_LABEL[rule] || rule}`}), flag),
            el("div", {class: "num"}, value, el("span", {class: "small", text: ` · limit ${lim}`})),
            bar);
}

function renderTrial(view, data) {
  const t = view.trial;
  const counter = $("counter");
  if (t && t.position && t.total) {
    counter.textContent = `${t.practice ? "practice " : ""}trial ${t.position}/${t.total}`;
  } else {
    counter.textContent = view.status === "finished" ? "finished" : "–";
  }
  counter.dataset.position = t && t.position ? String(t.position) : "";
  const info = [];
  if (t) {
    if (t.method) info.push(t.method);
    if (t.parameter) info.push(`${t.parameter} = ${num(t.value)}` +
                               (t.start_value !== null ? ` (start ${num(t.start_value)})` : ""));
    if (t.image) info.push(t.image);
    if (t.attempt) info.push(`attempt ${t.attempt + 1}`);
    if (t.elapsed_s !== null) info.push(`${t.elapsed_s.toFixed(1)} s`);
  }
  $("trial-info").textContent = info.join(" · ");
  let state = view.state || "";
  if (view.text) state += `: “${view.text}”`;
  if (view.since && view.status === "running") state += ` (${ago(data.server_time, view.since)})`;
  if (view.end) {
    $("state").textContent = `the session finished: ${ending(view.end, data.server_time)}`;
  } else {
    $("state").textContent = state ? (view.status === "running" ? "now: " : "last state: ") +
                                     state : "";
  }
  $("state").dataset.end = view.end ? (view.end.state || "") : "";
  $("eta").textContent = view.status === "running" && view.eta_s !== null ?
    `ETA ${duration(view.eta_s)}` : "";
  const tot = view.totals || {};
  const lat = tot.latency_ms || {};
  const bits = [];
  if (tot.frames !== undefined) bits.push(`this run: ${tot.frames} frames, ${tot.dropped} dropped`);
  if (lat.n) bits.push(`gaze-to-flip p50 ${ms(lat.p50)}, p95 ${ms(lat.p95)}`);
  for (const k of ["pauses", "breaks", "disconnections"]) {
    if (tot[k]) bits.push(`${tot[k]} ${k}`);
  }
  $("totals").textContent = bits.join(" · ");

  const rules = $("rules");
  if (t && t.rules) {
    rules.replaceChildren(...Object.entries(t.rules).map(([rule, r]) => ruleRow(rule, r, t)));
  } else {
    const none = view.end ? "no trial on screen: the session has ended" :
                 view.status === "stopped" ? "no trial on screen when it stopped" :
                 "no trial on screen yet";
    rules.replaceChildren(el("p", {text: none}));
  }
  const label = view.status === "running" && view.state === "trial" ? "the trial on screen" :
                "the last trial";
  $("rules-note").textContent = (t ? `Figures of ${label} (attempt ${t.attempt + 1}), as ` +
    "fovexp analyze will judge it. " : "") + (view.rules_apply ? "" :
    "Dry run: the analysis applies R11-R13 to participants' trials only; the flags show " +
    "what they would do.");
}

function renderTracker(view, data) {
  const tr = view.tracker || {};
  const st = tr.connected === false || view.state === "disconnected" ? "LOST" : "connected";
  $("tracker").textContent = `${tr.name || "?"}: ${st}` +
    (view.status === "running" ? "" : " (as last written)");
  $("tracker").className = "info" + (st === "LOST" ? " warn" : "");
  const q = tr.quality;
  let qt = "no validation yet";
  if (q && q.skipped) qt = `not calibrated (${q.skipped})`;
  else if (q) {
    qt = `last validation: accuracy ${num(q.accuracy_deg)}°, central ${num(q.central_accuracy_deg)}°, ` +
         `data loss ${pct(q.data_loss)}; ${q.passed ? "passed" : "FAILED"}` +
         (q.accepted ? ", accepted" : "");
  }
  $("quality").textContent = qt;
  const events = (tr.events || []).slice(-5).reverse();
  $("events").replaceChildren(...events.map((e) =>
    el("li", {text: `${e.kind} ${ago(data.server_time, e.time)}`})));
}

function renderTrials(view) {
  const rows = (view.trials || []).slice().reverse();
  const tbody = $("trials").tBodies[0];
  if (!rows.length) {
    tbody.replaceChildren(el("tr", {}, el("td", {colspan: "8", text: "none logged yet"})));
    return;
  }
  tbody.replaceChildren(...rows.map((r) => el("tr", {class: r.flagged.length ? "over" : ""},
    el("td", {class: "num", text: `${r.index}${r.practice ? " (practice)" : ""}`}),
    el("td", {text: r.method || ""}),
    el("td", {text: r.image || ""}),
    el("td", {class: "num", text: num(r.final_value)}),
    el("td", {class: "num", text: pct(r.blanked_fraction)}),
    el("td", {class: "num", text: r.frames ? `${r.dropped_frames}/${r.frames}` :
                                             String(r.dropped_frames ?? "–")}),
    el("td", {class: "num", text: ms(r.latency_p95_ms)}),
    el("td", {}, ...(r.flagged.length ? r.flagged.map((f) =>
      el("span", {class: "flag soft", "data-rule": f, text: f.split(" ")[0]})) :
      [el("span", {class: "okmark", text: "ok"})])))));
}

function render(data) {
  lastData = data;
  renderLists(data);
  const view = data.view;
  $("empty").hidden = !!view;
  $("session").hidden = !view;
  if (!view) return;
  if (!key) key = view.key;
  $("who").textContent = `${view.experiment} / ${view.participant} / ${view.session}`;
  const status = $("status");
  status.textContent = view.status === "stopped" ? "not responding" : view.status;
  status.className = "badge " + view.status;
  $("dry").hidden = !view.dry_run;
  const why = $("why");
  why.hidden = !view.why;
  why.textContent = view.why ? `${view.why}. The last state it wrote is shown.` : "";
  renderTrial(view, data);
  renderGaze(view);
  renderTracker(view, data);
  renderTrials(view);
  const rep = view.report;
  $("report-card").hidden = !(rep && view.status === "finished");
  if (rep) {
    const p = $("report");
    p.replaceChildren();
    if (rep.url) {
      p.append(el("a", {href: rep.url + (token ? "?token=" + encodeURIComponent(token) : ""),
                        target: "_blank", rel: "noopener", text: "fovexp analyze's report"}));
      if (rep.note) p.append(" – " + rep.note);
    } else {
      p.textContent = rep.note || "";
    }
  }
  const skipped = view.skipped || [];
  $("skipped-card").hidden = !skipped.length;
  $("skipped").replaceChildren(...skipped.map((s) => el("li", {text: s})));
}

connect();
