/* fleetlink console: polls the console's JSON and renders it with DOM calls (no inline HTML from
 * data, no external libraries). Pages: "fleet" (site list), "site" (health, graph, robots,
 * mappings, editor, commands), "login" (server-rendered form only). */
"use strict";

(() => {
  const body = document.body;
  const BASE = body.dataset.base || "/";
  const POLL_MS = Math.max(200, Number(body.dataset.pollMs) || 1000);
  const SVG = "http://www.w3.org/2000/svg";

  // -- small helpers -------------------------------------------------------------------------
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [key, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (key === "class") node.className = value;
      else if (key === "text") node.textContent = value;
      else if (key === "dataset") Object.assign(node.dataset, value);
      else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
      else node.setAttribute(key, value === true ? "" : String(value));
    }
    for (const child of children.flat()) {
      if (child === null || child === undefined || child === false) continue;
      node.append(child instanceof Node ? child : document.createTextNode(String(child)));
    }
    return node;
  }

  function fmtRate(value) {
    if (value === null || value === undefined) return "…";
    if (value === 0) return "0";
    if (Math.abs(value) < 10) return value.toFixed(1);
    return Math.round(value).toLocaleString("en");
  }

  function fmtBytes(n) {
    if (n === null || n === undefined) return "?";
    const units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let i = 0;
    while (n >= 1024 && i < units.length - 1) { n /= 1024; i += 1; }
    return `${i === 0 ? n : n.toFixed(1)} ${units[i]}`;
  }

  function fmtSeconds(s) {
    if (s === null || s === undefined) return "?";
    if (s < 1) return `${Math.round(s * 1000)} ms`;
    if (s < 120) return `${s.toFixed(1)} s`;
    return `${Math.round(s / 60)} min`;
  }

  function fmtInt(n) { return (n || 0).toLocaleString("en"); }

  function replaceChildren(node, ...children) {
    node.replaceChildren(...children.flat().filter((c) => c !== null && c !== undefined));
  }

  function setUpdated(text, bad) {
    const node = document.getElementById("updated");
    if (!node) return;
    node.textContent = text;
    node.classList.toggle("bad", Boolean(bad));
  }

  async function api(method, path, data) {
    const headers = { Accept: "application/json" };
    const init = { method, headers, credentials: "same-origin" };
    if (method !== "GET") headers["X-Fleetlink-Console"] = "1";
    if (data !== undefined) {
      headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(data);
    }
    const abort = new AbortController();
    const timer = setTimeout(() => abort.abort(), 20000);
    init.signal = abort.signal;
    let response;
    try {
      response = await fetch(BASE + path, init);
    } finally {
      clearTimeout(timer);
    }
    if (response.status === 401) {
      location.assign(`${BASE}login?next=${encodeURIComponent(location.pathname)}`);
      throw new Error("signed out");
    }
    let payload;
    try {
      payload = await response.json();
    } catch (err) {
      payload = { ok: false, error: `HTTP ${response.status}`, fields: {} };
    }
    return { status: response.status, data: payload };
  }

  /* run `task` now and again `every` ms after each run ends (never two at once) */
  function loop(task, every) {
    const run = async () => {
      try {
        await task();
      } catch (err) {
        setUpdated(`connection problem: ${err.message || err}; retrying`, true);
      }
      setTimeout(run, every);
    };
    run();
  }

  function badge(state) {
    return el("span", { class: `badge ${state || "unknown"}`, text: state || "unknown" });
  }

  // -- commands panel (fleet and site pages) -------------------------------------------------
  async function refreshCommands() {
    const box = document.getElementById("commands");
    if (!box) return;
    const { status, data } = await api("GET", "api/commands");
    if (status !== 200) {
      replaceChildren(box, el("span", { class: "bad", text: data.error || `error ${status}` }));
      return;
    }
    if (!data.available) {
      box.className = "muted";
      replaceChildren(box, el("span", { id: "commands-unavailable", text: data.reason }));
      return;
    }
    box.className = "";
    const rows = [
      ["command records read", data.records], ["forwarded to robots", data.forwards],
      ["settled by a repeater", data.settled], ["expired before forwarding", data.expired_before_forward],
      ["expired unacknowledged", data.expired_unacknowledged], ["dead-lettered", data.dead_lettered],
      ["in flight", data.in_flight], ["status records written", data.status_records_written],
      ["repeater status batches", data.status_batches], ["repeater heartbeats", data.heartbeats],
      ["robots known (registrations)", data.robots_known],
    ];
    for (const [result, count] of Object.entries(data.results || {})) rows.push([`repeater result: ${result}`, count]);
    const mappings = (data.mappings || []).map((m) => el("li", {}, el("code", { text: m.name }), ` ${m.from} → ${m.to}`));
    replaceChildren(box,
      el("table", { class: "table compact", id: "commands-table" },
        el("tbody", {}, rows.map(([label, value]) => el("tr", {}, el("th", { text: label }),
          el("td", { class: "num", text: fmtInt(value) }))))),
      mappings.length ? el("ul", { class: "plain" }, mappings) : null);
  }

  // -- fleet page ------------------------------------------------------------------------------
  async function refreshFleetDelivery() {
    const box = document.getElementById("fleet-delivery");
    if (!box) return;
    const { status, data } = await api("GET", "api/delivery");
    if (status !== 200 || !data.available) {
      replaceChildren(box, el("span", { text: data.error || "not available on this process" }));
      return;
    }
    box.className = "";
    const head = deliveryLines(data, data.latency);
    const rows = (data.uplinks || []).map((u) => el("tr", { dataset: { uplink: u.uplink, site: u.site } },
      el("td", {}, el("code", { text: u.uplink })), el("td", { text: u.site }),
      el("td", { class: "num", text: fmtInt((u.batches || {}).ok) }),
      el("td", { class: "num", text: fmtInt(u.records) }), el("td", { class: "num", text: fmtInt(u.dead_lettered) })));
    const topics = Object.entries(data.topics || {}).map(([topic, t]) => el("tr", { dataset: { topic } },
      el("td", {}, el("code", { text: topic })), el("td", { class: "num", text: fmtInt(t.acked) }),
      el("td", { class: "num", text: fmtRate(t.rate) })));
    replaceChildren(box, el("div", { class: "cards" }, card("All uplinks", "fleet-delivery-total", ...head)),
      el("h3", { text: "Per uplink and site" }),
      el("table", { class: "table compact", id: "fleet-uplinks" }, el("thead", {}, el("tr", {},
        ["Uplink", "Site", "Batches acked", "Records in Kafka", "Dead-lettered"].map((h) => el("th", { text: h })))),
        el("tbody", {}, rows)),
      el("h3", { text: "Per Kafka topic" }),
      el("table", { class: "table compact", id: "fleet-topics" }, el("thead", {}, el("tr", {},
        ["Kafka topic", "Records acknowledged", "rec/s"].map((h) => el("th", { text: h })))), el("tbody", {}, topics)));
  }

  function fleetPage() {
    loop(refreshFleetDelivery, Math.max(POLL_MS, 2000));
    const tbody = document.querySelector("#sites tbody");
    loop(async () => {
      const { status, data } = await api("GET", "api/sites");
      if (status !== 200) throw new Error(data.error || `HTTP ${status}`);
      const rows = data.sites.map((s) => el("tr", { dataset: { site: s.site } },
        el("td", {}, el("a", { href: `${BASE}sites/${encodeURIComponent(s.site)}`, text: s.site })),
        el("td", { text: s.edge_id || "" }),
        el("td", {}, s.error ? el("span", { class: "bad", text: s.error }) : badge(s.state)),
        el("td", { class: "num", text: s.robots ?? "?" }),
        el("td", { text: s.wan_link_up === true ? "up" : s.wan_link_up === false ? "down" : "not known yet" }),
        el("td", { class: "num", text: s.problems ?? "?" })));
      if (!rows.length) rows.push(el("tr", {}, el("td", { colspan: 6, class: "muted", text: "no site answered" })));
      replaceChildren(tbody, rows);
      setUpdated(`updated ${new Date().toLocaleTimeString()}`);
    }, Math.max(POLL_MS, 2000));
    loop(refreshCommands, Math.max(POLL_MS, 3000));
  }

  // -- site page: health -----------------------------------------------------------------------
  function card(title, id, ...lines) {
    return el("div", { class: "card", id }, el("h3", { text: title }), lines.map((l) => el("div", {}, l)));
  }

  /* every uplink's figures added up: batches, records in Kafka, latency of the last minute */
  function deliveryLines(d, l) {
    if (!d) return [el("span", { class: "muted", text: "not available: this process cannot ask the uplinks" })];
    const lines = [];
    const ok = (d.batches || {}).ok || 0;
    lines.push(el("strong", { id: "delivered-batches", text: ok ? `${fmtInt(ok)} batches acknowledged` : "no batch delivered yet" }),
      `${fmtInt(d.records)} records in Kafka, now ${fmtRate(d.rate)}/s · ${fmtInt(d.dead_lettered)} dead-lettered`,
      el("span", { class: "muted", text: `from ${d.uplink_count} uplink(s)` +
        (d.batches && d.batches.error ? ` · ${fmtInt(d.batches.error)} batches to retry` : "") }));
    if (l) {
      lines.push(`median ${l.p50_ms} ms · p95 ${l.p95_ms} ms · max ${l.max_ms} ms`,
        el("span", { class: "muted", text: `${fmtInt(l.batches)} batches, last ${l.window_s} s` }));
    } else {
      lines.push(el("span", { class: "muted", text: "no batch delivered in the last minute" }));
    }
    return lines;
  }

  function renderHealth(view) {
    const health = view.health || {};
    const status = view.status;
    const cards = [];
    const degraded = Object.keys(health.degraded_mappings || {});
    cards.push(card("State", "health-state", badge(health.state),
      degraded.length ? `degraded mappings: ${degraded.join(", ")}` : null));
    const link = status && status.wan_link_up !== undefined ? status.wan_link_up : health.wan_link_up;
    const wanLines = [el("strong", { class: link === false ? "bad" : "", text:
      link === true ? "up" : link === false ? "down: records are held in the spool" : "not known yet (nothing sent)" })];
    if (status) {
      for (const [stream, w] of Object.entries(status.wan || {})) {
        wanLines.push(`${stream}: ${fmtInt(w.batches_acked)} batches acked, ${fmtInt(w.batches_retried)} retried, ` +
          `${fmtInt(w.in_flight)} in flight`);
        if (w.outage_s) wanLines.push(el("span", { class: "bad", text: `outage for ${fmtSeconds(w.outage_s)}` }));
        if (w.last_error && w.healthy === false) wanLines.push(el("span", { class: "bad", text: w.last_error }));
      }
    }
    cards.push(card("WAN link", "health-wan", ...wanLines));
    const spool = [];
    if (status) {
      for (const s of status.streams || []) {
        const fill = s.fill === null ? "" : ` (${(s.fill * 100).toFixed(1)} %)`;
        spool.push(el("span", { class: "spool-line", dataset: { stream: s.stream, depth: s.depth } },
          `${s.stream}: ${fmtInt(s.depth)} records, ${fmtBytes(s.bytes)}${fill}, oldest ${fmtSeconds(s.oldest_age_s)}`));
      }
      if (!spool.length) spool.push("no buffer open");
    } else {
      for (const [stream, fill] of Object.entries(health.spool_fill || {})) {
        spool.push(`${stream}: ${(fill * 100).toFixed(1)} % full`);
      }
      spool.push(el("span", { class: "muted", text: "depth and age: not reported by this site" }));
    }
    cards.push(card("Spool", "health-spool", ...spool));
    cards.push(card("Kafka delivery", "health-latency", ...deliveryLines(view.delivery, view.latency)));
    const registered = (view.robots || []).filter((r) => r.state === "registered").length;
    cards.push(card("Robots", "health-robots", `${registered} registered`,
      (view.robots || []).length > registered ? `${view.robots.length - registered} lost` : null));
    replaceChildren(document.getElementById("health"), cards);
    const problems = (health.problems || []).map((p) => el("li", { class: p.severity },
      el("strong", { text: `${p.component} ${p.subject}` }), `: ${p.reason} — ${p.detail}`));
    replaceChildren(document.getElementById("problems"), problems);
    const state = document.getElementById("site-state");
    state.className = `badge ${health.state || "unknown"}`;
    state.textContent = health.state || "unknown";
    document.getElementById("site-edge").textContent = view.edge_id ? `edge ${view.edge_id}` : "";
    const errors = Object.entries(view.errors || {});
    const box = document.getElementById("read-errors");
    box.hidden = errors.length === 0;
    replaceChildren(box, errors.map(([part, message]) => el("div", {}, `${part}: ${message}`)));
  }

  // -- site page: graph ------------------------------------------------------------------------
  function node(n, lines, rate) {
    return el("div", { class: `node ${n.state || ""} ${n.degraded ? "degraded" : ""} ${n.mapped === false ? "unmapped" : ""}`,
      id: `node-${n.id}`, dataset: { nodeId: n.id, rate: rate === null || rate === undefined ? "" : String(rate) },
      title: n.detail || n.label },
    el("div", { class: "label", text: n.label }), lines.map((l) => el("div", { class: "line" }, l)));
  }

  /* what the filter box and the "unmapped topics" switch leave visible (robots, topics, mappings) */
  const view = { filter: "", unmapped: false };

  function matches(...texts) {
    const wanted = view.filter.trim().toLowerCase();
    return !wanted || texts.some((t) => String(t || "").toLowerCase().includes(wanted));
  }

  function visibleGraph(graph) {
    const topics = graph.topics.filter((t) => (view.unmapped || t.mapped) &&
      matches(t.label, t.robot.slice(2)));
    const robotsWithTopics = new Set(topics.map((t) => t.robot));
    const robots = graph.robots.filter((r) => robotsWithTopics.has(r.id) || (!view.filter.trim() ?
      true : matches(r.label)));
    const shown = new Set([...robots, ...topics, ...graph.mappings, ...graph.kafka].map((n) => n.id));
    const edges = graph.edges.filter((e) => shown.has(e.from) && shown.has(e.to));
    const hidden = graph.topics.length - topics.length;
    return { ...graph, robots, topics, edges, hidden };
  }

  function renderGraph(full) {
    const graph = visibleGraph(full);
    const cols = {};
    for (const col of document.querySelectorAll("#graph .col")) cols[col.dataset.col] = col.querySelector(".nodes");
    replaceChildren(cols.robots, graph.robots.map((n) => node(n, [n.detail], null)));
    replaceChildren(cols.topics, graph.topics.map((n) => node(n,
      [el("span", { class: "rate", text: n.mapped ? `${fmtRate(n.rate)} msg/s` : "not mapped" })], n.rate)));
    replaceChildren(cols.mappings, graph.mappings.map((n) => node(n, [
      el("span", { class: "rate", text: `in ${fmtRate(n.in)}/s · out ${fmtRate(n.out)}/s` }),
      n.filtered ? el("span", { class: "rate muted", text: `filtered by its stages ${fmtRate(n.filtered)}/s` }) : null,
      (n.drop || n.dead) ? el("span", { class: "rate drop", text: `lost ${fmtRate(n.drop)}/s` +
        (n.dead ? ` · dead-lettered ${fmtRate(n.dead)}/s` : "") }) : null], n.out)));
    const backlog = full.backlog;
    const head = [];
    if (backlog && backlog.records > 0) {
      head.push(el("div", { class: `backlog ${backlog.oldest_age_s > 5 ? "bad" : ""}`, id: "kafka-backlog" },
        `${fmtInt(backlog.records)} record(s) waiting in the spool, oldest ${fmtSeconds(backlog.oldest_age_s)}`));
    }
    if (!full.kafka_reported) {
      head.push(el("div", { class: "muted small", id: "kafka-unreported", text: "no uplink reported what Kafka acknowledged" }));
    }
    replaceChildren(cols.kafka, head, graph.kafka.map((n) => node(n, [
      el("span", { class: "rate", text: n.rate === null || n.rate === undefined ? "… in Kafka" :
        `${n.approx ? "≈ " : ""}${fmtRate(n.rate)} rec/s in Kafka` }),
      el("span", { class: "rate muted small", text: `mapped ${fmtRate(n.mapped)}/s` })], n.rate)));
    const notes = [];
    if (graph.hidden) notes.push(`${graph.hidden} topic(s) hidden by the filter or as not mapped`);
    const elsewhere = Object.entries(full.elsewhere || {});
    if (elsewhere.length) {
      notes.push(`${elsewhere.length} other ROS namespace(s) seen on the network, not registered at this site: ` +
        elsewhere.map(([ns, n]) => `${ns} (${n})`).join(", "));
    }
    const box = document.getElementById("graph-notes");
    if (box) box.textContent = notes.join(" · ");
    return graph;
  }

  /* curves between the nodes, in the graph box's own coordinates (measured now: layout is
   * computed on demand, so the lines always match the boxes as they are) */
  function drawEdges(graph) {
    const box = document.getElementById("graph");
    const svg = document.getElementById("graph-lines");
    const origin = box.getBoundingClientRect();
    svg.setAttribute("width", String(box.offsetWidth));
    svg.setAttribute("height", String(box.offsetHeight));
    const paths = [];
    for (const edge of graph.edges) {
      const a = document.getElementById(`node-${edge.from}`);
      const b = document.getElementById(`node-${edge.to}`);
      if (!a || !b) continue;
      const ra = a.getBoundingClientRect();
      const rb = b.getBoundingClientRect();
      const x1 = ra.right - origin.left;
      const y1 = ra.top + ra.height / 2 - origin.top;
      const x2 = rb.left - origin.left;
      const y2 = rb.top + rb.height / 2 - origin.top;
      const mid = (x1 + x2) / 2;
      const path = document.createElementNS(SVG, "path");
      path.setAttribute("d", `M${x1},${y1} C${mid},${y1} ${mid},${y2} ${x2},${y2}`);
      const rate = edge.rate;
      path.setAttribute("class", rate ? "edge live" : "edge idle");
      path.setAttribute("stroke-width", String(rate ? 1.5 + Math.min(4, Math.log10(1 + rate) * 1.5) : 1));
      paths.push(path);
    }
    svg.replaceChildren(...paths);
  }

  // -- site page: robots and mappings ----------------------------------------------------------
  function fmtTime(seconds) {
    if (seconds === null || seconds === undefined) return "not known";
    return new Date(seconds * 1000).toLocaleString("en-GB", { hour12: false });
  }

  function renderRobots(robots, site) {
    const tbody = document.querySelector("#robots tbody");
    const shown = robots.filter((r) => matches(r.robot, r.robot_type, r.state));
    const rows = shown.map((r) => el("tr", { dataset: { robot: r.robot } },
      el("td", {}, el("a", { href: `${BASE}sites/${encodeURIComponent(site)}/robots/${encodeURIComponent(r.robot)}`,
        text: r.robot })),
      el("td", { text: r.robot_type }), el("td", {}, badge(r.state)),
      el("td", { text: fmtTime(r.registered_at) }),
      el("td", { text: r.explicit ? "registered explicitly" : "discovered" })));
    if (!rows.length) {
      rows.push(el("tr", {}, el("td", { colspan: 5, class: "muted",
        text: robots.length ? "no robot matches the filter" : "no robot registered" })));
    }
    replaceChildren(tbody, rows);
  }

  function stageText(stage) {
    const args = Object.entries(stage).filter(([k]) => k !== "type" && k !== "name")
      .map(([k, v]) => `${k}=${typeof v === "object" ? JSON.stringify(v) : v}`);
    return `${stage.type}(${args.join(", ")})`;
  }

  const removal = { name: null, until: 0 };

  function renderMappings(view, editor) {
    const tbody = document.querySelector("#mappings tbody");
    const rows = view.mappings.filter((m) => matches(m.name, m.from, m.to, m.robot_type)).map((m) => {
      const r = m.rates || {};
      const c = m.counters || {};
      const confirming = removal.name === m.name && Date.now() < removal.until;
      const stageCounts = (m.stage_counters || []).map((s) =>
        el("div", { class: "muted small", text: `${s.name}: ${fmtInt(s.received)} in, ${fmtInt(s.dropped)} dropped` }));
      return el("tr", { dataset: { mapping: m.name } },
        el("td", {}, el("strong", { text: m.name }), el("div", { class: "muted small",
          text: `${m.robot_type ? `${m.robot_type} template` : "site"} · ${m.origin}` }),
          (m.issues || []).map((i) => el("div", { class: "bad small", text: `${i.reason}: ${i.detail}` }))),
        el("td", {}, el("code", { text: m.from }), " → ", el("code", { text: m.to }),
          el("div", { class: "muted small", text: `key ${m.key || "{robot}"}${m.type ? ` · ${m.type}` : ""}` })),
        el("td", {}, (m.stages || []).map((s) => el("div", {}, el("code", { text: stageText(s) }))), stageCounts),
        el("td", { class: "num", text: fmtRate(r.received) }),
        el("td", { class: "num", text: fmtRate(r.emitted) }),
        el("td", { class: "num" }, el("span", { class: "muted", title: "left out by its stages, as configured",
          text: fmtRate(r.filtered) }), " · ", el("span", { class: r.dropped ? "drop" : "", title: "lost (stage errors, other ROS types)",
          text: fmtRate(r.dropped) })),
        el("td", { class: "small totals" }, `${fmtInt(c.received)} in · ${fmtInt(c.emitted)} out`,
          el("br"), `${fmtInt(c.dropped)} dropped · ${fmtInt(c.dead_lettered)} dead-lettered`),
        el("td", { class: "actions" },
          el("button", { type: "button", class: "edit", onclick: () => editor.edit(m), text: "Edit" }),
          el("button", { type: "button", class: confirming ? "remove danger" : "remove",
            text: confirming ? "Confirm remove" : "Remove", onclick: () => editor.remove(m.name) })));
    });
    if (!rows.length) rows.push(el("tr", {}, el("td", { colspan: 8, class: "muted", text: "no mapping" })));
    replaceChildren(tbody, rows);
  }

  // -- site page: the mapping editor -----------------------------------------------------------
  function mappingEditor(site, refresh) {
    const form = document.getElementById("mapping-form");
    const fields = ["name", "robot_type", "from", "to", "key", "type", "delivery", "stages"];
    const title = document.getElementById("form-title");
    const submit = document.getElementById("submit-mapping");
    const cancel = document.getElementById("cancel-edit");
    const result = document.getElementById("form-result");
    const dry = document.getElementById("dry-run");
    const enc = encodeURIComponent(site);
    let editing = null;

    const values = () => Object.fromEntries(fields.map((f) => [f, form.elements[f].value]));
    const say = (text, bad) => { result.textContent = text; result.classList.toggle("bad", Boolean(bad)); };

    function clearErrors() {
      for (const box of form.querySelectorAll(".field-error")) { box.textContent = ""; box.hidden = true; }
      for (const input of form.querySelectorAll("[aria-invalid]")) {
        input.removeAttribute("aria-invalid");
        input.classList.remove("invalid");
      }
    }

    function showErrors(errors) {
      for (const [field, messages] of Object.entries(errors || {})) {
        const box = document.getElementById(`error-${field}`) || document.getElementById("error-_form");
        box.textContent = [box.textContent, ...messages].filter(Boolean).join(" ");
        box.hidden = false;
        const input = form.elements[field];
        if (input) {
          input.classList.add("invalid");
          input.setAttribute("aria-invalid", "true");
        }
      }
    }

    function reset() {
      editing = null;
      form.reset();
      form.elements.name.readOnly = false;
      title.textContent = "Add a mapping";
      submit.textContent = "Add mapping";
      cancel.hidden = true;
      clearErrors();
    }

    function refused(data) {
      showErrors(data.fields && Object.keys(data.fields).length ? data.fields : { _form: [data.error || "refused"] });
      say(data.error || "refused", true);
    }

    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      clearErrors();
      say("sending …");
      const path = editing ? `api/sites/${enc}/mappings/${encodeURIComponent(editing)}` : `api/sites/${enc}/mappings`;
      const { data } = await api(editing ? "PUT" : "POST", path, values());
      if (!data.ok) { refused(data); return; }
      say(`mapping ${data.result.name} ${data.result.status}`);
      reset();
      refresh();
    });

    document.getElementById("dry-run-button").addEventListener("click", async () => {
      clearErrors();
      say("trying …");
      const { data } = await api("POST", `api/sites/${enc}/dry-run`, values());
      if (!data.ok) { refused(data); dry.hidden = true; return; }
      const matches = data.result.matches || [];
      const named = matches.slice(0, 4).map((m) => `${m.topic} → ${m.kafka_topic} (key ${m.key})`);
      if (matches.length > 4) named.push(`and ${matches.length - 4} more`);
      say(`dry run: ${matches.length} topic(s) would be mapped now${named.length ? `: ${named.join(", ")}` : ""}`);
      dry.hidden = false;
      replaceChildren(dry, el("h3", { text: `Dry run of ${data.result.mapping}` }),
        el("table", { class: "table compact", id: "dry-run-table" },
          el("thead", {}, el("tr", {}, ["ROS topic", "Robot", "Registered", "Kafka topic", "Key", "Type fits"]
            .map((h) => el("th", { text: h })))),
          el("tbody", {}, matches.length ? matches.map((m) => el("tr", {},
            el("td", {}, el("code", { text: m.topic })), el("td", { text: m.robot || "—" }),
            el("td", { text: m.registered ? "yes" : "no" }), el("td", {}, el("code", { text: m.kafka_topic })),
            el("td", { text: m.key }), el("td", { class: m.type_ok ? "" : "bad", text: m.type_ok ? "yes" : "no" })))
            : el("tr", {}, el("td", { colspan: 6, class: "muted", text: "no discovered topic matches" })))));
    });

    cancel.addEventListener("click", () => { reset(); say(""); });

    return {
      edit(mapping) {
        reset();
        editing = mapping.name;
        const set = (f, v) => { form.elements[f].value = v === null || v === undefined ? "" : v; };
        set("name", mapping.name);
        form.elements.name.readOnly = true;
        set("robot_type", mapping.robot_type);
        set("from", mapping.from);
        set("to", mapping.to);
        set("key", mapping.key);
        set("type", mapping.type);
        set("delivery", mapping.delivery);
        set("stages", (mapping.stages || []).length ? mapping.stages.map((s) => `- ${JSON.stringify(s)}`).join("\n") : "");
        title.textContent = `Change mapping ${mapping.name}`;
        submit.textContent = "Save changes";
        cancel.hidden = false;
        say("");
        document.getElementById("editor").scrollIntoView({ behavior: "smooth" });
      },
      async remove(name) {
        if (removal.name !== name || Date.now() >= removal.until) {
          removal.name = name;
          removal.until = Date.now() + 5000;
          refresh();
          return;
        }
        removal.name = null;
        const { data } = await api("DELETE", `api/sites/${enc}/mappings/${encodeURIComponent(name)}`);
        if (!data.ok) { say(data.error || "refused", true); return; }
        say(`mapping ${name} removed`);
        refresh();
      },
      robotTypes(names) {
        const select = form.elements.robot_type;
        const have = [...select.options].map((o) => o.value).slice(1).join("\n");
        if (have === names.join("\n")) return;
        const chosen = select.value;
        replaceChildren(select, el("option", { value: "", text: "— site-level mapping —" }),
          names.map((n) => el("option", { value: n, text: n })));
        select.value = names.includes(chosen) ? chosen : "";
      },
    };
  }


  // -- charts: the last hour, as small SVG line charts ------------------------------------------
  const COLOURS = ["#1f6feb", "#1a7f37", "#b35900", "#c62828", "#8250df", "#0a7ea4", "#6e7781", "#bf3989"];

  function chart(title, columns, names, id) {
    const width = 420;
    const height = 140;
    const pad = { l: 44, r: 8, t: 8, b: 18 };
    const t = columns.t || [];
    const svg = document.createElementNS(SVG, "svg");
    svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
    svg.setAttribute("class", "chart");
    if (id) svg.setAttribute("id", id);
    const values = names.flatMap((n) => (columns[n] || []).filter((v) => v !== null && v !== undefined));
    const max = Math.max(1e-9, ...values);
    const t0 = t.length ? t[0] : 0;
    const t1 = t.length ? Math.max(t[t.length - 1], t0 + 1) : 1;
    const x = (v) => pad.l + ((v - t0) / (t1 - t0)) * (width - pad.l - pad.r);
    const y = (v) => height - pad.b - (v / max) * (height - pad.t - pad.b);
    const axis = document.createElementNS(SVG, "path");
    axis.setAttribute("d", `M${pad.l},${pad.t} V${height - pad.b} H${width - pad.r}`);
    axis.setAttribute("class", "axis");
    svg.append(axis);
    const label = (text, lx, ly, anchor) => {
      const node = document.createElementNS(SVG, "text");
      node.setAttribute("x", String(lx));
      node.setAttribute("y", String(ly));
      node.setAttribute("text-anchor", anchor || "start");
      node.textContent = text;
      svg.append(node);
    };
    label(fmtRate(max), pad.l - 4, pad.t + 8, "end");
    label("0", pad.l - 4, height - pad.b, "end");
    if (t.length) label(`${Math.round((t1 - t0) / 60)} min`, width - pad.r, height - 4, "end");
    const legend = el("div", { class: "legend" });
    names.forEach((name, i) => {
      const data = columns[name] || [];
      let d = "";
      let pen = false;
      data.forEach((v, j) => {
        if (v === null || v === undefined) { pen = false; return; }
        d += `${pen ? "L" : "M"}${x(t[j]).toFixed(1)},${y(v).toFixed(1)} `;
        pen = true;
      });
      const path = document.createElementNS(SVG, "path");
      path.setAttribute("d", d.trim() || `M${pad.l},${height - pad.b}`);
      path.setAttribute("class", "series");
      path.setAttribute("stroke", COLOURS[i % COLOURS.length]);
      path.dataset.series = name;
      path.dataset.points = String(data.filter((v) => v !== null && v !== undefined).length);
      svg.append(path);
      legend.append(el("span", { style: null }, el("strong", { text: "— ", class: `c${i}` }), name));
      legend.lastChild.firstChild.setAttribute("class", `swatch c${i % COLOURS.length}`);
    });
    return el("div", { class: "card" }, el("h3", { text: title }), svg, legend);
  }

  async function refreshHistory(site) {
    const box = document.getElementById("history-charts");
    if (!box) return;
    const { status, data } = await api("GET", `api/sites/${encodeURIComponent(site)}/history`);
    if (status !== 200 || !data.available) {
      replaceChildren(box, el("span", { class: "muted", text: data.reason || data.error || `HTTP ${status}` }));
      return;
    }
    const all = (data.site || {}).all || { t: [] };
    replaceChildren(box,
      chart("Records per second", all, ["received", "emitted", "acked"], "chart-rates"),
      chart("Dropped per second", all, ["filtered", "lost", "dead_lettered"], "chart-drops"),
      chart("Spool backlog (records)", all, ["backlog"], "chart-backlog"),
      chart("Oldest record waiting (s)", all, ["oldest_age_s"], "chart-lag"));
    const mappings = Object.entries(data.mappings || {}).filter(([name]) => matches(name));
    replaceChildren(document.getElementById("mapping-charts"), mappings.map(([name, cols]) =>
      chart(name, cols, ["received", "emitted", "filtered", "lost", "dead_lettered"], `chart-mapping-${name}`)));
  }

  // -- site page: robot types ------------------------------------------------------------------
  function robotTypes(site, refresh) {
    const form = document.getElementById("type-form");
    if (!form) return { render() {} };
    const enc = encodeURIComponent(site);
    const result = document.getElementById("type-result");
    const say = (text, bad) => { result.textContent = text; result.classList.toggle("bad", Boolean(bad)); };
    const admin = body.dataset.role === "admin" || body.dataset.role === "";
    const confirm = { name: null, until: 0 };
    function clear() {
      for (const box of form.querySelectorAll(".field-error")) { box.textContent = ""; box.hidden = true; }
    }
    function show(fields) {
      for (const [field, messages] of Object.entries(fields || {})) {
        const box = document.getElementById(`terror-${field}`) || document.getElementById("terror-_form");
        box.textContent = messages.join(" ");
        box.hidden = false;
      }
    }
    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      clear();
      const name = form.elements.name.value.trim();
      if (!name) { show({ name: ["a name is needed"] }); return; }
      say("saving …");
      const { data } = await api("PUT", `api/sites/${enc}/robot-types/${encodeURIComponent(name)}`,
        { match: form.elements.match.value, mappings: form.elements.mappings.value });
      if (!data.ok) { show(data.fields && Object.keys(data.fields).length ? data.fields : { _form: [data.error] }); say(data.error || "refused", true); return; }
      say(`robot type ${name} ${data.result.status}`);
      form.reset();
      refresh();
    });
    for (const input of form.elements) if (!admin) input.disabled = true;
    if (!admin) say("only an admin changes robot types", false);
    return {
      render(types) {
        const tbody = document.querySelector("#robot-types tbody");
        const rows = (types || []).map((t) => {
          const confirming = confirm.name === t.name && Date.now() < confirm.until;
          return el("tr", { dataset: { type: t.name } },
            el("td", {}, el("strong", { text: t.name })), el("td", {}, el("code", { text: t.match })),
            el("td", { text: (t.mappings || []).join(", ") }), el("td", { text: (t.robots || []).join(", ") }),
            el("td", { text: t.origin }),
            el("td", { class: "actions" },
              el("button", { type: "button", class: "edit", text: "Edit", disabled: !admin, onclick: () => {
                form.elements.name.value = t.name;
                form.elements.match.value = t.match;
                form.elements.mappings.value = "";
                form.scrollIntoView({ behavior: "smooth" });
              } }),
              el("button", { type: "button", class: confirming ? "remove danger" : "remove", disabled: !admin,
                text: confirming ? "Confirm remove" : "Remove", onclick: async () => {
                  if (confirm.name !== t.name || Date.now() >= confirm.until) {
                    confirm.name = t.name; confirm.until = Date.now() + 5000; refresh(); return;
                  }
                  confirm.name = null;
                  const { data } = await api("DELETE", `api/sites/${enc}/robot-types/${encodeURIComponent(t.name)}`);
                  say(data.ok ? `robot type ${t.name} removed` : data.error || "refused", !data.ok);
                  refresh();
                } })));
        });
        if (!rows.length) rows.push(el("tr", {}, el("td", { colspan: 6, class: "muted", text: "no robot type" })));
        replaceChildren(tbody, rows);
      },
    };
  }

  // -- robot page ------------------------------------------------------------------------------
  function robotPage() {
    const site = body.dataset.site;
    const robot = body.dataset.robot;
    const path = `api/sites/${encodeURIComponent(site)}/robots/${encodeURIComponent(robot)}`;
    const sent = [];
    const refresh = async () => {
      const { status, data } = await api("GET", path);
      if (status !== 200) throw new Error(data.error || `HTTP ${status}`);
      const reg = data.registration;
      const state = document.getElementById("robot-state");
      state.className = `badge ${reg ? reg.state : "unknown"}`;
      state.textContent = reg ? reg.state : "not registered here";
      document.getElementById("robot-type").textContent = reg ?
        `${reg.robot_type} · since ${fmtTime(reg.registered_at)} · ${reg.explicit ? "registered explicitly" : "discovered"}` : "";
      const latest = data.latest || {};
      const values = latest.values || {};
      const box = document.getElementById("latest");
      box.className = "latest";
      const cards = Object.entries(values).map(([topic, v]) => el("div", { class: "card", dataset: { topic } },
        el("h3", {}, el("code", { text: topic }), el("span", { class: "muted small", text: ` ${v.type}` })),
        v.link ? el("div", {}, el("a", { href: v.link, rel: "noopener noreferrer", target: "_blank", text: v.link })) : null,
        v.picture && v.picture.startsWith("data:image/") ? el("img", { class: "picture", src: v.picture, alt: `${topic} at ${fmtTime(v.at)}` }) : null,
        el("pre", { class: "value", text: v.error || JSON.stringify(v.value, null, 1).slice(0, 4000) }),
        el("div", { class: "muted small", text: `at ${fmtTime(v.at)}` })));
      replaceChildren(box, cards.length ? el("div", { class: "cards" }, cards) :
        el("span", { class: "muted", text: data.errors && data.errors.latest ? data.errors.latest :
          "no mapped topic of this robot published within the wait" }));
      replaceChildren(document.querySelector("#robot-topics tbody"), (data.topics || []).map((t) => el("tr", { dataset: { topic: t.topic } },
        el("td", {}, el("code", { text: t.topic })), el("td", { text: (t.types || []).join(", ") }),
        el("td", { text: t.mapped ? t.mappings.map((m) => `${m.mapping} → ${m.kafka_topic}`).join(", ") : "not mapped" }))));
      replaceChildren(document.querySelector("#robot-history tbody"), (data.history || []).map((h) => el("tr", {},
        el("td", { text: fmtTime(h.at) }), el("td", {}, badge(h.event)), el("td", { text: h.robot_type }),
        el("td", { text: h.reason }))));
      const errors = Object.entries(data.errors || {}).filter(([k]) => k !== "latest");
      const eb = document.getElementById("read-errors");
      eb.hidden = !errors.length;
      replaceChildren(eb, errors.map(([k, m]) => el("div", { text: `${k}: ${m}` })));
      setUpdated(`updated ${new Date().toLocaleTimeString()}`);
    };
    const form = document.getElementById("command-form");
    const result = document.getElementById("command-result");
    const say = (text, bad) => { result.textContent = text; result.classList.toggle("bad", Boolean(bad)); };
    (async () => {
      const { data } = await api("GET", "api/command-mappings");
      const select = form.elements.mapping;
      if (!data.available) {
        for (const input of form.elements) input.disabled = true;
        say(data.reason || "commands are not available here");
        return;
      }
      replaceChildren(select, (data.mappings || []).map((m) => el("option", { value: m.name, text: `${m.name} (${m.type} → ${m.to})` })));
      if (!["operator", "admin", ""].includes(body.dataset.role)) {
        for (const input of form.elements) input.disabled = true;
        say("only an operator or an admin sends commands");
      }
    })();
    const renderSent = async () => {
      if (!sent.length) return;
      const { data } = await api("GET", `api/commands/status?ids=${sent.map((c) => encodeURIComponent(c.command_id)).join(",")}`);
      const statuses = data.statuses || {};
      replaceChildren(document.querySelector("#sent-commands tbody"), sent.map((c) => {
        const seen = statuses[c.command_id] || [];
        const last = seen.length ? seen[seen.length - 1] : null;
        return el("tr", { dataset: { command: c.command_id, status: last ? last.status : "sent" } },
          el("td", {}, el("code", { text: c.command_id })), el("td", { text: c.mapping }),
          el("td", { text: new Date(c.at).toLocaleTimeString() }),
          el("td", { class: last ? `status-${last.status}` : "" }, last ? `${last.status}${last.site ? ` at ${last.site}` : ""}${last.detail ? ` (${last.detail})` : ""}` :
            "in Kafka: waiting for the uplink and the repeater", seen.length > 1 ? el("div", { class: "muted small",
              text: seen.map((s) => s.status).join(" → ") }) : null));
      }));
    };
    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      for (const box of form.querySelectorAll(".field-error")) { box.textContent = ""; box.hidden = true; }
      say("sending …");
      const { data } = await api("POST", "api/commands/send", { mapping: form.elements.mapping.value, robot, value: form.elements.value.value });
      if (!data.ok) {
        for (const [field, messages] of Object.entries(data.fields || { _form: [data.error] })) {
          const box = document.getElementById(`cerror-${field}`) || document.getElementById("cerror-_form");
          box.textContent = messages.join(" ");
          box.hidden = false;
        }
        say(data.error || "refused", true);
        return;
      }
      sent.unshift({ ...data.result, at: Date.now() });
      say(`command ${data.result.command_id} is in Kafka (${data.result.topic}, offset ${data.result.offset})`);
      renderSent();
    });
    loop(refresh, Math.max(POLL_MS, 3000));
    loop(renderSent, Math.max(POLL_MS, 1000));
  }

  // -- dead letters ----------------------------------------------------------------------------
  function deadLettersPage() {
    const site = body.dataset.site;
    const state = document.getElementById("dead-letters-state");
    const filter = document.getElementById("filter");
    const detail = document.getElementById("dead-letter-detail");
    let records = [];
    const render = () => {
      view.filter = filter.value;
      const shown = records.filter((r) => matches(r.reason, r.stage, r.topic, r.key, r.site, r.edge));
      replaceChildren(document.querySelector("#dead-letters tbody"), shown.map((r) => el("tr", { dataset: { offset: r.offset, partition: r.partition } },
        el("td", { text: new Date(r.timestamp_ms).toLocaleString("en-GB", { hour12: false }) }),
        el("td", { text: `${r.site || "?"} / ${r.edge || "?"}` }), el("td", {}, el("code", { text: r.topic || "—" })),
        el("td", { text: r.stage }), el("td", { class: "reason", text: r.reason }), el("td", {}, el("code", { text: r.key })),
        el("td", { class: "num", text: fmtInt(r.size) }),
        el("td", { class: "actions" },
          el("button", { type: "button", class: "show", text: "Bytes", onclick: () => {
            detail.hidden = false;
            replaceChildren(detail, el("h3", { text: `partition ${r.partition}, offset ${r.offset}: ${fmtInt(r.size)} bytes` }),
              el("div", { class: "hex", id: "dead-letter-hex", text: r.value_hex.replace(/(.{2})/g, "$1 ").trim() + (r.truncated ? " …" : "") }),
              el("a", { href: `${BASE}api/dead-letters/${r.partition}/${r.offset}/raw`, id: "dead-letter-download", text: "Download the raw bytes" }));
          } })))));
      state.textContent = `${shown.length} of ${records.length} dead letter(s) shown`;
    };
    filter.addEventListener("input", render);
    loop(async () => {
      const { status, data } = await api("GET", `api/dead-letters?limit=200${site ? `&site=${encodeURIComponent(site)}` : ""}`);
      if (status !== 200) throw new Error(data.error || `HTTP ${status}`);
      if (!data.available) { state.textContent = data.reason; return; }
      records = data.records || [];
      render();
      setUpdated(`updated ${new Date().toLocaleTimeString()}`);
    }, Math.max(POLL_MS, 3000));
  }

  // -- audit -------------------------------------------------------------------------------------
  function auditPage() {
    loop(async () => {
      const { status, data } = await api("GET", "api/audit?limit=200");
      if (status !== 200) throw new Error(data.error || `HTTP ${status}`);
      replaceChildren(document.querySelector("#audit tbody"), (data.records || []).map((r) => el("tr", { dataset: { action: r.action } },
        el("td", { text: fmtTime(r.at) }), el("td", { text: r.user }), el("td", { text: r.role }),
        el("td", {}, el("code", { text: r.action })), el("td", { text: r.site || "" }), el("td", { text: r.target || "" }),
        el("td", { class: r.ok ? "" : "bad", text: String(r.status) }),
        el("td", {}, el("code", { class: "small", text: JSON.stringify(r.detail) })))));
      setUpdated(`updated ${new Date().toLocaleTimeString()}`);
    }, Math.max(POLL_MS, 3000));
  }

  // -- site page -------------------------------------------------------------------------------
  function sitePage() {
    const site = body.dataset.site;
    let last = null;
    let editor = null;
    const refresh = async () => {
      const { status, data } = await api("GET", `api/sites/${encodeURIComponent(site)}`);
      if (status !== 200) throw new Error(data.error || `HTTP ${status}`);
      last = data;
      editor.robotTypes(data.robot_types || []);
      renderHealth(data);
      const shown = renderGraph(data.graph);
      renderRobots(data.robots || [], site);
      renderMappings(data, editor);
      types.render(data.robot_type_details || []);
      drawEdges(shown);
      setUpdated(`updated ${new Date().toLocaleTimeString()}`);
    };
    editor = mappingEditor(site, () => refresh().catch((err) => setUpdated(String(err), true)));
    const types = robotTypes(site, () => refresh().catch((err) => setUpdated(String(err), true)));
    const filter = document.getElementById("filter");
    const unmapped = document.getElementById("show-unmapped");
    const rerender = () => {
      view.filter = filter.value;
      view.unmapped = unmapped.checked;
      if (!last) return;
      const shown = renderGraph(last.graph);
      renderRobots(last.robots || [], site);
      renderMappings(last, editor);
      drawEdges(shown);
    };
    filter.addEventListener("input", rerender);
    unmapped.addEventListener("change", rerender);
    loop(refresh, POLL_MS);
    loop(refreshCommands, Math.max(POLL_MS, 3000));
    loop(() => refreshHistory(site), Math.max(POLL_MS * 5, 5000));
    new ResizeObserver(() => { if (last) drawEdges(visibleGraph(last.graph)); }).observe(document.getElementById("graph"));
  }

  const pages = { fleet: fleetPage, site: sitePage, robot: robotPage, "dead-letters": deadLettersPage, audit: auditPage };
  const start = pages[body.dataset.page];
  if (start) start();
})();
