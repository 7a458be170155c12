/* jitroute console: draws the pages from the console's JSON API (same server; nothing is loaded from elsewhere).
   Maps are SVG in an equirectangular frame (longitudes stretched by cos of the middle latitude); land is the
   product's land mask as a picture; weather is a coloured grid with arrows pointing where the flow goes to. */
"use strict";

const SVGNS = "http://www.w3.org/2000/svg";
const STATUS_COLOUR = { ok: "#1f7a38", late: "#d9600b", failed: "#c0002a", infeasible: "#c0002a" };
const RAMPS = {  // colour stops per weather variable (value in its unit → colour)
  wind: [[0, "#f7fbff"], [10, "#b5d8ec"], [20, "#6aaed6"], [30, "#3d7fc0"], [40, "#8c55a8"], [55, "#b3134f"]],
  waves: [[0, "#f7fcf0"], [1, "#ccebc5"], [2.5, "#7bccc4"], [4, "#2b8cbe"], [6, "#0c4a8a"], [9, "#4a0c6b"]],
  currents: [[0, "#fff7fb"], [0.5, "#d0d1e6"], [1, "#a6bddb"], [2, "#3690c0"], [3, "#034e7b"]],
};
const FLOW_WORD = { wind: "the wind blows to", waves: "the waves run to", currents: "the current sets to" };

function el(tag, attrs, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined) continue;
    if (k === "text") e.textContent = v; else if (k === "cls") e.className = v; else e.setAttribute(k, v);
  }
  for (const k of kids.flat()) if (k !== null && k !== undefined) e.append(k instanceof Node ? k : String(k));
  return e;
}
function sv(tag, attrs, ...kids) {
  const e = document.createElementNS(SVGNS, tag);
  for (const [k, v] of Object.entries(attrs || {})) if (v !== null && v !== undefined) e.setAttribute(k, v);
  for (const k of kids.flat()) if (k !== null && k !== undefined) e.append(k instanceof Node ? k : String(k));
  return e;
}
function title(text) { return sv("title", {}, text); }
const ESC = { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" };
function esc(x) { return String(x).replace(/[&<>"']/g, c => ESC[c]); }
async function getJSON(url) {
  const r = await fetch(url, { credentials: "same-origin" });
  const body = await r.json().catch(() => ({ error: `${url}: HTTP ${r.status}` }));
  if (!r.ok) throw new Error(body.error || `${url}: HTTP ${r.status}`);
  return body;
}
function fail(err) {
  const main = document.getElementById("main");
  main.replaceChildren(el("div", { cls: "error", text: String(err.message || err) }));
}

/* times: ISO UTC strings → "2020-12-01 12:00Z"; short form "12-01 12:00" */
function utc(iso) { return iso ? iso.slice(0, 16).replace("T", " ") + "Z" : "–"; }
function utcShort(iso) { return iso ? iso.slice(5, 16).replace("T", " ") : "–"; }
function num(x, d = 1) { return x === null || x === undefined || Number.isNaN(x) ? "–" : Number(x).toFixed(d); }
function hours(a, b) { return (Date.parse(b) - Date.parse(a)) / 3.6e6; }
function statusCell(s) { return el("td", { cls: `status-${s}`, text: s || "–" }); }
function td(text, cls) { return el("td", { cls, text: text === undefined || text === null ? "–" : String(text) }); }
function table(headers, rows, id) {
  const head = el("tr", {}, headers.map(h => el("th", { cls: h.endsWith(" ") ? "num" : null, text: h.trim() })));
  return el("div", { cls: "tablebox" }, el("table", { id }, el("thead", {}, head), el("tbody", {}, rows)));
}
function colourAt(ramp, x) {
  if (x === null || x === undefined) return null;
  let i = 0;
  while (i < ramp.length - 2 && x > ramp[i + 1][0]) i++;
  const [x0, c0] = ramp[i], [x1, c1] = ramp[i + 1];
  const f = Math.max(0, Math.min(1, (x - x0) / (x1 - x0)));
  const p = c => [1, 3, 5].map(k => parseInt(c.slice(k, k + 2), 16));
  const a = p(c0), b = p(c1);
  return a.map((v, k) => Math.round(v + f * (b[k] - v)));
}

/* ---- the map: an SVG frame over a box (west, east, south, north; longitudes continuous) ---- */
class MapView {
  constructor(box, extent) {
    const k = Math.cos(((extent.south + extent.north) / 2) * Math.PI / 180);
    let { west, east, south, north } = extent;
    const W = 1000;
    let H = W * (north - south) / ((east - west) * k);
    if (H > 640) { const dx = (north - south) / k * W / 640; const c = (west + east) / 2; west = c - dx / 2; east = c + dx / 2; H = 640; }
    if (H < 380) { const dy = 380 * (east - west) * k / W; const c = (south + north) / 2; south = Math.max(-85, c - dy / 2); north = Math.min(85, c + dy / 2); H = W * (north - south) / ((east - west) * k); }
    Object.assign(this, { west, east, south, north, W, H });
    this.svg = sv("svg", { id: "map", viewBox: `0 0 ${W} ${Math.round(H)}`, role: "img",
                           "data-west": west.toFixed(3), "data-east": east.toFixed(3), "data-south": south.toFixed(3), "data-north": north.toFixed(3) });
    this.layers = {};
    for (const name of ["weather", "land", "arrows", "grid", "tracks", "marks", "ships", "labels"]) {
      this.layers[name] = sv("g", { class: `layer-${name}` });
      this.svg.append(this.layers[name]);
    }
    box.replaceChildren(this.svg);
    const q = `west=${west}&east=${east}&south=${south}&north=${north}`;
    this.layers.land.append(sv("image", { href: `/api/land.png?${q}&px=1000`, x: 0, y: 0, width: W, height: H, preserveAspectRatio: "none" }));
    this.graticule();
  }
  x(lon) { return (lon - this.west) / (this.east - this.west) * this.W; }
  y(lat) { return (this.north - lat) / (this.north - this.south) * this.H; }
  path(points) { return points.map((p, i) => `${i ? "L" : "M"}${this.x(p[1]).toFixed(1)},${this.y(p[0]).toFixed(1)}`).join(""); }
  graticule() {
    const span = Math.max(this.east - this.west, this.north - this.south);
    const step = span > 90 ? 20 : span > 40 ? 10 : span > 16 ? 5 : 2;
    const g = this.layers.grid;
    const lonLabel = l => { const w = ((l + 540) % 360) - 180; return w === -180 ? "180°" : `${Math.abs(w)}°${w < 0 ? "W" : w > 0 ? "E" : ""}`; };
    for (let l = Math.ceil(this.west / step) * step; l <= this.east; l += step) {
      g.append(sv("line", { x1: this.x(l), x2: this.x(l), y1: 0, y2: this.H, stroke: "#7f98ad", "stroke-width": 0.5, "stroke-dasharray": "3 4" }));
      g.append(sv("text", { x: this.x(l) + 3, y: this.H - 4, "font-size": 11, fill: "#3a5166" }, lonLabel(l)));
    }
    for (let l = Math.ceil(this.south / step) * step; l <= this.north; l += step) {
      g.append(sv("line", { x1: 0, x2: this.W, y1: this.y(l), y2: this.y(l), stroke: "#7f98ad", "stroke-width": 0.5, "stroke-dasharray": "3 4" }));
      g.append(sv("text", { x: 3, y: this.y(l) - 3, "font-size": 11, fill: "#3a5166" }, `${Math.abs(l)}°${l < 0 ? "S" : l > 0 ? "N" : ""}`));
    }
  }
  arrow(x, y, toDeg, len, colour, width = 1.3) {
    const a = toDeg * Math.PI / 180, dx = Math.sin(a) * len, dy = -Math.cos(a) * len;
    const x0 = x - dx / 2, y0 = y - dy / 2, x1 = x + dx / 2, y1 = y + dy / 2;
    const h = Math.max(3, len * 0.35), s = 0.45;
    const hx1 = x1 - h * (Math.sin(a) * Math.cos(s) - Math.cos(a) * Math.sin(s)), hy1 = y1 + h * (Math.cos(a) * Math.cos(s) + Math.sin(a) * Math.sin(s));
    const hx2 = x1 - h * (Math.sin(a) * Math.cos(s) + Math.cos(a) * Math.sin(s)), hy2 = y1 + h * (Math.cos(a) * Math.cos(s) - Math.sin(a) * Math.sin(s));
    return sv("path", { d: `M${x0.toFixed(1)},${y0.toFixed(1)}L${x1.toFixed(1)},${y1.toFixed(1)}M${hx1.toFixed(1)},${hy1.toFixed(1)}L${x1.toFixed(1)},${y1.toFixed(1)}L${hx2.toFixed(1)},${hy2.toFixed(1)}`,
                        stroke: colour, "stroke-width": width, fill: "none", "stroke-linecap": "round" });
  }
  drawWeather(w) {
    const g = this.layers.weather;
    g.replaceChildren();
    this.layers.arrows.replaceChildren();
    g.setAttribute("data-valid", w.valid_utc);
    g.setAttribute("data-var", w.var);
    const ny = w.lat.length, nx = w.lon.length, ramp = RAMPS[w.var];
    if (ny < 2 || nx < 2) return;
    const canvas = document.createElement("canvas");
    canvas.width = nx; canvas.height = ny;
    const ctx = canvas.getContext("2d"), img = ctx.createImageData(nx, ny);
    const north = w.lat[0] > w.lat[ny - 1];  // rows from north to south on the canvas
    for (let i = 0; i < ny; i++) {
      const row = w.magnitude[north ? i : ny - 1 - i];
      for (let j = 0; j < nx; j++) {
        const c = colourAt(ramp, row[j]), o = 4 * (i * nx + j);
        if (c) { img.data[o] = c[0]; img.data[o + 1] = c[1]; img.data[o + 2] = c[2]; img.data[o + 3] = 170; }
      }
    }
    ctx.putImageData(img, 0, 0);
    const dlat = Math.abs(w.lat[1] - w.lat[0]), dlon = w.lon[1] - w.lon[0];
    const latN = Math.max(w.lat[0], w.lat[ny - 1]) + dlat / 2, latS = Math.min(w.lat[0], w.lat[ny - 1]) - dlat / 2;
    const x0 = this.x(w.lon[0] - dlon / 2), x1 = this.x(w.lon[nx - 1] + dlon / 2);
    g.append(sv("image", { href: canvas.toDataURL(), x: x0, y: this.y(latN), width: x1 - x0, height: this.y(latS) - this.y(latN), preserveAspectRatio: "none" }));
    const cell = Math.abs(this.x(w.lon[1]) - this.x(w.lon[0]));
    const every = Math.max(1, Math.ceil(26 / cell));
    const arrows = sv("g", { class: "arrows" });
    for (let i = 0; i < ny; i += every) for (let j = 0; j < nx; j += every) {
      const m = w.magnitude[i][j], d = w.to_deg[i][j];
      if (m === null || d === null) continue;
      const x = this.x(w.lon[j]), y = this.y(w.lat[i]);
      if (x < 0 || x > this.W || y < 0 || y > this.H) continue;
      const len = 8 + 14 * Math.min(1, m / (w.max || 1));
      arrows.append(this.arrow(x, y, d, len, "#24323f", 1.1));
    }
    this.layers.arrows.append(arrows);
  }
}

function weatherLegend(w) {
  const ramp = RAMPS[w.var], top = ramp[ramp.length - 1][0];
  const stops = ramp.map(([x, c]) => `${c} ${(100 * x / top).toFixed(0)}%`).join(", ");
  const bar = el("span", { cls: "bar" });
  bar.style.background = `linear-gradient(to right, ${stops})`;
  return el("div", { cls: "legend", id: "weather-legend" },
    el("b", { text: `${w.label} [${w.unit}]` }), "0", bar, `${top}+ ${w.unit}`,
    el("span", { text: `· arrows: where ${FLOW_WORD[w.var].replace("the ", "")} (longer = stronger; max ${num(w.max)} ${w.unit} in view)` }),
    el("span", { cls: "note", text: `· cycle ${utc(w.cycle)} + ${w.step_h} h` }));
}

/* the weather controls (variable, valid-time slider) over a map; `onTime(validIso)` is told each change */
function weatherControls(map, weather, onTime) {
  const box = el("div", { cls: "controls" });
  const legendBox = el("div", {});
  if (!weather || !weather.times.length) {
    box.append(el("span", { cls: "note", text: "no weather cube cycle to show" }));
    return [box, legendBox];
  }
  const times = weather.times;
  let idx = Math.max(0, times.findIndex(t => t.step_h === weather.default_step_h));
  const select = el("select", { id: "weather-var" },
    ["wind", "waves", "currents", "none"].map(v => el("option", { value: v, text: v === "none" ? "no weather" : v })));
  const slider = el("input", { id: "valid-slider", type: "range", min: 0, max: times.length - 1, step: 1, value: idx, "aria-label": "valid time" });
  const label = el("span", { id: "valid-time" });
  let pending = 0;
  async function refresh() {
    const t = times[Number(slider.value)], v = select.value;
    label.textContent = `valid ${utc(t.valid_utc)} (cycle ${utc(weather.cycle)} + ${t.step_h} h)`;
    label.setAttribute("data-valid", t.valid_utc);
    if (onTime) onTime(t.valid_utc);
    if (v === "none") { map.layers.weather.replaceChildren(); map.layers.arrows.replaceChildren(); legendBox.replaceChildren(); return; }
    const ticket = ++pending;
    const q = `west=${map.west}&east=${map.east}&south=${map.south}&north=${map.north}`;
    const w = await getJSON(`/api/weather?${q}&var=${v}&cycle=${encodeURIComponent(weather.cycle)}&step_h=${t.step_h}`);
    if (ticket !== pending) return;  // a newer move of the slider won
    map.drawWeather(w);
    legendBox.replaceChildren(weatherLegend(w));
  }
  slider.addEventListener("input", () => refresh().catch(fail));
  select.addEventListener("change", () => refresh().catch(fail));
  box.append(el("label", {}, "Weather ", select), el("label", {}, "Time ", slider), label);
  refresh().catch(fail);
  return [box, legendBox];
}

/* ---- Fleet ---- */
async function fleetPage(main) {
  const at = new URLSearchParams(location.search).get("at");
  const d = await getJSON("/api/fleet" + (at ? `?at=${encodeURIComponent(at)}` : ""));
  const counts = Object.entries(d.counts).map(([k, v]) => `${v} ${k}`).join(", ") || "no voyages";
  const run = d.run;
  main.replaceChildren(
    el("h1", { text: `Fleet · ${d.voyages.length} voyages` }),
    el("p", { cls: "summary", id: "fleet-summary" },
      "Positions at ", el("b", { text: utc(d.as_of_utc) }), ` (${d.as_of_note}) · `,
      run ? `newest run ${run.run_id} (${run.status}), cycle ${utc(run.cycle)}, ${num(run.cycle_age_h, 0)} h old at its time · ` : "no routing run yet · ",
      `${counts} · `, el("b", { cls: d.n_attention ? "attention" : null, text: `${d.n_attention} need attention` })));
  const mapBox = el("div", { cls: "mapbox" });
  main.append(mapBox);
  const map = new MapView(mapBox, d.extent);
  const [controls, legend] = weatherControls(map, d.weather, null);
  mapBox.before(controls);
  mapBox.after(legend);
  legend.after(el("div", { cls: "legend" },
    "plan ahead (dashed, by status) · track behind (grey) · ● ship now (on its plan) · ○ start of a ship's later voyage · ◆ last reported position",
    ...Object.entries(STATUS_COLOUR).slice(0, 3).map(([k, c]) => { const s = el("span", { cls: "dot" }); s.style.background = c; return el("span", {}, s, ` ${k}`); })));
  // a thousand voyages: each layer is written as one string (far cheaper than an element at a time)
  const tracks = [], marks = [], ships = [], labels = [], placed = [];
  const tag = (name, attrs, inner) => `<${name} ${Object.entries(attrs).map(([k, v]) => `${k}="${esc(v)}"`).join(" ")}>${inner || ""}</${name}>`;
  const tip = text => `<title>${esc(text)}</title>`;
  for (const v of d.voyages) {
    const colour = STATUS_COLOUR[v.status] || "#555";
    const about = `${v.vessel_name} · ${v.voyage_id} · ${v.dep_name} → ${v.arr_name} · ${v.status} · ETA ${utc(v.eta_utc)} · RTA ${utc(v.rta_utc)}`;
    if (v.behind.length) tracks.push(tag("path", { class: "track-behind", "data-voyage": v.voyage_id, d: map.path(v.behind), stroke: "#56606b", "stroke-width": 1.6, fill: "none" }));
    if (v.ahead.length) tracks.push(tag("path", { class: "track-ahead", "data-voyage": v.voyage_id, d: map.path(v.ahead), stroke: colour, "stroke-width": 1.8, "stroke-dasharray": "6 3", fill: "none" }, tip(about)));
    if (v.report) {
      const x = map.x(v.report.lon).toFixed(1), y = map.y(v.report.lat);
      marks.push(tag("path", { class: "report", "data-voyage": v.voyage_id, d: `M${x},${(y - 8).toFixed(1)}l8,8l-8,8l-8,-8Z`, fill: "#fff", stroke: "#333" }, tip(`${v.vessel_name}: ${v.report.source} ${utc(v.report.utc)}`)));
    }
    if (!v.position) continue;
    const x = map.x(v.position.lon), y = map.y(v.position.lat), href = `/voyage/${encodeURIComponent(v.voyage_id)}`;
    if (!v.current) {  // another voyage of a ship that is elsewhere now: where this one starts
      marks.push(tag("a", { href }, tag("circle", { class: "voyage-start", "data-voyage": v.voyage_id, cx: x.toFixed(1), cy: y.toFixed(1), r: 3.5, fill: "#fff", stroke: colour, "stroke-width": 1.5 },
        tip(`${about} · a later voyage of this ship (${v.position.phase})`))));
      continue;
    }
    ships.push(tag("a", { href }, tag("circle", { class: "ship", "data-voyage": v.voyage_id, "data-phase": v.position.phase, cx: x.toFixed(1), cy: y.toFixed(1), r: v.attention.length ? 6 : 4.5,
      fill: colour, stroke: v.attention.length ? "#000" : "#fff", "stroke-width": 1.5 }, tip(`${about} · ${v.position.phase}` + (v.attention.length ? ` · ${v.attention.join("; ")}` : "")))));
    // a label where it overlaps no other (the table lists every voyage)
    const name = v.vessel_name || v.voyage_id, w = 7 * name.length, lx = x + 7, ly = y - 6;
    if (lx + w < map.W && !placed.some(p => Math.abs(p[0] - lx) < (p[2] + w) / 2 + 4 && Math.abs(p[1] - ly) < 13)) {
      placed.push([lx, ly, w]);
      labels.push(tag("text", { x: lx.toFixed(1), y: ly.toFixed(1), "font-size": 11, fill: "#10202e", stroke: "#fff", "stroke-width": 3, "paint-order": "stroke" }, esc(name)));
    }
  }
  map.layers.tracks.innerHTML = tracks.join("");
  map.layers.marks.innerHTML = marks.join("");
  map.layers.ships.innerHTML = ships.join("");
  map.layers.labels.innerHTML = labels.join("");
  voyageTable(main, d.voyages);
}

/* the fleet's voyages as a table: those needing attention first; at most ROWS_SHOWN rows until asked for all, with a
   filter on vessel, voyage, ports and status (a thousand rows are slow to lay out and nobody reads them at once) */
const ROWS_SHOWN = 200;
function voyageTable(main, voyages) {
  const cell = (text, cls) => `<td${cls ? ` class="${cls}"` : ""}>${esc(text === null || text === undefined ? "–" : text)}</td>`;
  const row = v => `<tr data-voyage="${esc(v.voyage_id)}">` + cell(v.vessel_name)
    + `<td class="id" title="${esc(v.voyage_id)}"><a href="/voyage/${encodeURIComponent(v.voyage_id)}">${esc(v.voyage_id)}</a></td>`
    + cell(v.status, `status-${v.status}`) + cell(v.attention.join("; "), "wrap attention") + cell(`${v.dep_name} → ${v.arr_name}`)
    + cell(v.position ? v.position.phase + (v.current ? "" : " (later voyage)") : "–")
    + cell(utc(v.eta_utc)) + cell(utc(v.rta_utc)) + cell(v.eta_minus_rta_h === null ? "–" : (v.eta_minus_rta_h > 0 ? "+" : "") + num(v.eta_minus_rta_h, 1), "num")
    + cell(num(v.fuel_t, 1), "num") + cell(num(v.savings_pct, 1), "num") + "</tr>";
  const ordered = [...voyages.filter(v => v.attention.length), ...voyages.filter(v => !v.attention.length)];
  const text = v => `${v.vessel_name} ${v.voyage_id} ${v.dep_name} ${v.arr_name} ${v.status}`.toLowerCase();
  const box = table(["Vessel", "Voyage", "Status", "Attention", "Route", "Now", "ETA (UTC)", "RTA (UTC)", "ETA−RTA h ", "Fuel t ", "Saving % "], [], "voyages");
  const filter = el("input", { id: "voyage-filter", type: "search", placeholder: "filter: vessel, voyage, port, status", size: 36 });
  const count = el("span", { cls: "note", id: "voyage-count" });
  const all = el("button", { id: "show-all", type: "button" });
  let showAll = false;
  function draw() {
    const q = filter.value.trim().toLowerCase();
    const hits = q ? ordered.filter(v => text(v).includes(q)) : ordered;
    const shown = showAll ? hits : hits.slice(0, ROWS_SHOWN);
    box.querySelector("tbody").innerHTML = shown.map(row).join("");
    count.textContent = `${shown.length} of ${hits.length} voyages shown` + (q ? ` matching "${q}"` : "") + " · those needing attention first";
    all.textContent = `show all ${hits.length}`;
    all.hidden = shown.length === hits.length;
  }
  filter.addEventListener("input", draw);
  all.addEventListener("click", () => { showAll = true; draw(); });
  main.append(el("h2", { text: "Voyages" }), el("div", { cls: "controls" }, filter, count, all), box);
  draw();
}

/* ---- Voyage ---- */
function profileChart(legs, baseline) {
  const W = 720, H = 260, L = 50, R = 56, T = 16, B = 34;
  const t0 = Date.parse(legs[0].etd_utc), t1 = Date.parse(legs[legs.length - 1].eta_utc);
  const tEnd = baseline && baseline.hours ? Math.max(t1, t0 + baseline.hours * 3.6e6) : t1;
  const X = t => L + (t - t0) / (tEnd - t0) * (W - L - R);
  const vmax = Math.max(...legs.map(l => Math.max(l.sog_kn || 0, l.stw_kn || 0))) * 1.15 || 1;
  let cum = 0;
  const fuelPts = [[t0, 0]];
  for (const l of legs) { cum += (l.fuel_t || 0) + (l.wait_fuel_t || 0); fuelPts.push([Date.parse(l.eta_utc), cum]); }
  const fmax = Math.max(cum, baseline && baseline.fuel_t ? baseline.fuel_t : 0) * 1.1 || 1;
  const Yv = v => T + (1 - v / vmax) * (H - T - B), Yf = f => T + (1 - f / fmax) * (H - T - B);
  const svg = sv("svg", { id: "profile", viewBox: `0 0 ${W} ${H}`, width: W, height: H });
  const step = (key) => legs.map((l, i) => `${i ? "L" : "M"}${X(Date.parse(l.etd_utc)).toFixed(1)},${Yv(l[key] || 0).toFixed(1)}H${X(Date.parse(l.eta_utc)).toFixed(1)}`).join("");
  svg.append(sv("path", { d: step("stw_kn"), stroke: "#6aaed6", "stroke-width": 2, fill: "none" }));
  svg.append(sv("path", { d: step("sog_kn"), stroke: "#12324f", "stroke-width": 2, fill: "none" }));
  svg.append(sv("path", { d: fuelPts.map((p, i) => `${i ? "L" : "M"}${X(p[0]).toFixed(1)},${Yf(p[1]).toFixed(1)}`).join(""), stroke: "#d9600b", "stroke-width": 2, fill: "none" }));
  if (baseline && baseline.fuel_t && baseline.hours) {
    svg.append(sv("path", { d: `M${X(t0)},${Yf(0)}L${X(t0 + baseline.hours * 3.6e6)},${Yf(baseline.fuel_t)}`, stroke: "#d9600b", "stroke-width": 1.5, "stroke-dasharray": "5 4", fill: "none" },
      title(`constant-speed baseline: ${num(baseline.fuel_t)} t in ${num(baseline.hours)} h`)));
  }
  svg.append(sv("line", { x1: L, x2: L, y1: T, y2: H - B, stroke: "#445" }), sv("line", { x1: L, x2: W - R, y1: H - B, y2: H - B, stroke: "#445" }), sv("line", { x1: W - R, x2: W - R, y1: T, y2: H - B, stroke: "#445" }));
  for (let k = 0; k <= 4; k++) {
    svg.append(sv("text", { x: L - 4, y: Yv(vmax * k / 4) + 4, "font-size": 10, "text-anchor": "end" }, num(vmax * k / 4, 0)));
    svg.append(sv("text", { x: W - R + 4, y: Yf(fmax * k / 4) + 4, "font-size": 10, fill: "#b04a00" }, num(fmax * k / 4, 0)));
  }
  const hourMs = 3.6e6, every = [6, 12, 24, 48, 96].map(h => h * hourMs).find(e => (tEnd - t0) / e <= 8) || 192 * hourMs;
  for (let t = Math.ceil(t0 / every) * every; t <= tEnd; t += every) {
    svg.append(sv("line", { x1: X(t), x2: X(t), y1: H - B, y2: H - B + 4, stroke: "#445" }));
    svg.append(sv("text", { x: X(t), y: H - B + 15, "font-size": 10, "text-anchor": "middle" }, new Date(t).toISOString().slice(5, 13).replace("T", " ") + "Z"));
  }
  svg.append(sv("text", { x: 4, y: 11, "font-size": 11 }, "speed kn"), sv("text", { x: W - R - 2, y: 11, "font-size": 11, fill: "#b04a00" }, "fuel used t"),
    sv("text", { x: W / 2, y: H - 4, "font-size": 11, "text-anchor": "middle" }, "time (UTC, month-day hour)"));
  return el("div", { cls: "chart" }, svg, el("div", { cls: "legend" },
    swatch("#12324f"), "SOG", swatch("#6aaed6"), "STW", swatch("#d9600b"), "fuel used (plan)", swatchDash("#d9600b"), "constant-speed baseline arriving at the RTA"));
}
function swatch(c) { const s = el("span", { cls: "swatch" }); s.style.background = c; return s; }
function swatchDash(c) { const s = el("span", { cls: "swatch" }); s.style.background = `repeating-linear-gradient(to right, ${c} 0 5px, transparent 5px 9px)`; return s; }

function positionAt(track, times, iso) {
  const t = Date.parse(iso), ts = times.map(Date.parse);
  if (t <= ts[0]) return track[0];
  if (t >= ts[ts.length - 1]) return track[track.length - 1];
  let k = 1;
  while (ts[k] < t) k++;
  const f = (t - ts[k - 1]) / ((ts[k] - ts[k - 1]) || 1);
  return [track[k - 1][0] + f * (track[k][0] - track[k - 1][0]), track[k - 1][1] + f * (track[k][1] - track[k - 1][1])];
}

async function voyagePage(main, voyageId) {
  const d = await getJSON(`/api/voyage/${encodeURIComponent(voyageId)}`);
  const v = d.voyage, r = d.route;
  const late = r && r.eta_utc && r.rta_utc ? hours(r.rta_utc, r.eta_utc) : null;
  main.replaceChildren(
    el("h1", { text: `${v.vessel_name || v.imo} · voyage ${v.voyage_id}` }),
    el("p", { cls: "summary", id: "voyage-summary" }, `${v.dep_name} → ${v.arr_name} · departs ${utc(v.depart_utc)} · RTA ${utc(v.rta_utc)}`,
      r ? el("span", {}, " · plan ", el("span", { cls: `status-${r.status}`, text: r.status }),
        ` · ETA ${utc(r.eta_utc)}` + (late !== null ? ` (${late > 0 ? "+" : ""}${num(late, 1)} h vs RTA)` : "") +
        ` · ${num(r.fuel_t)} t · ${num(r.distance_nm, 0)} NM · run ${r.run_id} on cycle ${utc(r.cycle)}`) : " · no plan yet"),
    d.attention.length ? el("ul", { cls: "attention" }, d.attention.map(a => el("li", { text: a }))) : "",
    d.legs.length ? el("p", { cls: "downloads" }, "Download: ",
      el("a", { href: `/api/voyage/${encodeURIComponent(voyageId)}/route.rtz`, id: "download-rtz", text: "RTZ (ECDIS)" }),
      el("a", { href: `/api/voyage/${encodeURIComponent(voyageId)}/route.geojson`, id: "download-geojson", text: "GeoJSON" })) : "");
  const mapBox = el("div", { cls: "mapbox" });
  main.append(mapBox);
  const map = new MapView(mapBox, d.extent);
  for (const e of d.earlier_tracks) map.layers.tracks.append(sv("path", { class: "track-earlier", d: map.path(e.track), stroke: "#7a5b9a", "stroke-width": 1.4, "stroke-dasharray": "3 3", fill: "none" }, title(`earlier plan, run ${e.run_id}`)));
  if (d.track.length) {
    map.layers.tracks.append(sv("path", { class: "track-plan", "data-voyage": v.voyage_id, d: map.path(d.track), stroke: STATUS_COLOUR[r.status] || "#333", "stroke-width": 2.4, fill: "none" }));
    // weather met on each leg (from the plan): an arrow where the wind blows to, at the leg's middle
    d.legs.forEach((l, i) => {
      const x = map.x((l.lon0 + l.lon1) / 2), y = map.y((l.lat0 + l.lat1) / 2);
      if (l.wind_dir_deg !== null) map.layers.marks.append(sv("g", { class: "leg-wind" }, map.arrow(x, y, (l.wind_dir_deg + 180) % 360, 10 + Math.min(14, (l.wind_kn || 0) / 3), "#8c1d40", 1.6),
        title(`leg ${l.leg}: wind ${num(l.wind_kn)} kn from ${num(l.wind_dir_deg, 0)}°, Hs ${num(l.hs_m)} m from ${num(l.wave_dir_deg, 0)}°, ${utcShort(l.etd_utc)}–${utcShort(l.eta_utc)} UTC`)));
    });
    const span = hours(d.times[0], d.times[d.times.length - 1]), every = span > 96 ? 24 : span > 36 ? 12 : 6;
    let next = Math.ceil(Date.parse(d.times[0]) / (every * 3.6e6)) * every * 3.6e6;
    const tEnd = Date.parse(d.times[d.times.length - 1]);
    for (; next <= tEnd; next += every * 3.6e6) {
      const iso = new Date(next).toISOString(), p = positionAt(d.track, d.times, iso), x = map.x(p[1]), y = map.y(p[0]);
      map.layers.marks.append(sv("circle", { class: "time-mark", cx: x, cy: y, r: 2.5, fill: "#fff", stroke: "#111" }));
      map.layers.labels.append(sv("text", { x: x + 5, y: y + 12, "font-size": 10, fill: "#111", stroke: "#fff", "stroke-width": 3, "paint-order": "stroke" }, iso.slice(5, 13).replace("T", " ") + "Z"));
    }
    for (const [p, name] of [[d.track[0], v.dep_name], [d.track[d.track.length - 1], v.arr_name]]) {
      map.layers.labels.append(sv("text", { x: map.x(p[1]) + 6, y: map.y(p[0]) - 6, "font-size": 12, "font-weight": 600, fill: "#10202e", stroke: "#fff", "stroke-width": 3, "paint-order": "stroke" }, name || ""));
    }
  }
  const ship = sv("circle", { id: "ship-at-time", r: 6, fill: "#ffd400", stroke: "#000", "stroke-width": 1.5, visibility: "hidden" });
  map.layers.ships.append(ship);
  const onTime = iso => {
    if (!d.track.length) return;
    const p = positionAt(d.track, d.times, iso);
    ship.setAttribute("cx", map.x(p[1])); ship.setAttribute("cy", map.y(p[0])); ship.setAttribute("visibility", "visible");
  };
  const [controls, legend] = weatherControls(map, d.weather, onTime);
  mapBox.before(controls);
  mapBox.after(legend);
  legend.after(el("div", { cls: "legend" }, "plan (by status) · ○ time marks (UTC) · ● where the ship is at the valid time · ",
    el("span", { style: null, text: "→ wind met on each leg (points where it blows to)" }), d.earlier_tracks.length ? " · dashed purple: earlier plans" : ""));
  if (d.legs.length) {
    main.append(el("h2", { text: `Legs (${d.legs.length})` }), table(
      ["Leg ", "ETD (UTC)", "ETA (UTC)", "Dist NM ", "Course ° ", "rpm ", "STW kn ", "SOG kn ", "Wind kn ", "from ° ", "Hs m ", "from ° ", "Current kn ", "Wait h ", "Fuel t "],
      d.legs.map(l => el("tr", {}, td(l.leg, "num"), td(utc(l.etd_utc)), td(utc(l.eta_utc)), td(num(l.dist_nm), "num"), td(num(l.course_deg, 0), "num"),
        td(num(l.rpm, 1), "num"), td(num(l.stw_kn, 2), "num"), td(num(l.sog_kn, 2), "num"), td(num(l.wind_kn, 1), "num"), td(num(l.wind_dir_deg, 0), "num"),
        td(num(l.hs_m, 2), "num"), td(num(l.wave_dir_deg, 0), "num"), td(num(l.current_kn, 2), "num"), td(num(l.wait_h, 1), "num"), td(num((l.fuel_t || 0) + (l.wait_fuel_t || 0), 2), "num"))),
      "legs"));
    main.append(el("h2", { text: "Speed and fuel along the plan" }),
      profileChart(d.legs, r ? { fuel_t: r.honest_baseline_fuel_t, hours: r.honest_baseline_hours } : null));
  }
  main.append(el("h2", { text: "Plans made for this voyage (newest first) and their constant-speed baselines" }), table(
    ["Run", "Made (UTC)", "Trigger", "Status", "Cycle", "Starts from", "ETA (UTC)", "Fuel t ", "Baseline t ", "Baseline rpm ", "Saving % ", "of which route % ", "Reason"],
    d.plans.map(p => el("tr", {}, td(p.run_id), td(utc(p.run_started_at)), td(p.trigger), statusCell(p.status), td(utc(p.cycle)),
      td(`${p.start_kind || "–"} ${utcShort(p.start_utc)}`), td(utc(p.eta_utc)), td(num(p.fuel_t), "num"), td(num(p.honest_baseline_fuel_t), "num"),
      td(num(p.honest_baseline_rpm), "num"), td(num(p.savings_total_pct, 2), "num"), td(num(p.savings_route_pct, 2), "num"), el("td", { cls: "wrap", text: p.reason || "" }))),
    "plans"));
  const a = d.actual;
  if (a) {
    main.append(el("h2", { text: "Plan against what was sailed (noon reports)" }), a.n_reports ? table(
      ["Reports ", "Planned fuel t ", "Actual fuel t ", "Fuel error % ", "Planned ETA", "Arrived (last report)", "Arrival error h "],
      [el("tr", {}, td(a.n_reports, "num"), td(num(a.planned_fuel_t), "num"), td(num(a.actual_fuel_t), "num"), td(num(a.fuel_error_pct), "num"),
        td(utc(a.planned_eta_utc)), td(utc(a.actual_arrival_utc)), td(num(a.arrival_error_h), "num"))], "actual")
      : el("p", { cls: "note", text: "no noon reports sailed on this voyage yet" }));
  }
}

/* ---- Fleet plan ---- */
async function planPage(main) {
  const d = await getJSON("/api/plan");
  if (!d.plan) { main.replaceChildren(el("h1", { text: "Fleet plan" }), el("p", { text: "no active fleet plan: `jitroute plan fleet` makes one" })); return; }
  const p = d.plan;
  main.replaceChildren(el("h1", { text: `Fleet plan ${p.plan_id}` }),
    el("p", { cls: "summary", id: "plan-summary" }, `${p.solve_status} (${p.solver}, gap ${num(100 * (p.gap || 0), 2)} %${p.stopped_by ? `; search: ${p.stopped_by}` : ""}) · made ${utc(p.created_at)} for ${utc(p.as_of_utc)} · `,
      `${p.n_assigned} of ${p.n_contracts} contracts given to ${p.n_vessels_used} of ${d.rows.length} vessels · ${p.n_unassigned} left · fuel ${num(p.fuel_t, 0)} t · total cost ${num(p.total_cost, 0)} (fuel ${num(p.fuel_cost, 0)} + out of service ${num(p.out_of_service_cost, 0)} + penalties ${num(p.penalty_cost, 0)})`));
  const rowH = 34, L = 170, W = 1200, R = 20, T = 28, H = T + rowH * d.rows.length + 10;
  const t0 = Date.parse(d.start_utc), t1 = Date.parse(d.end_utc);
  const X = t => L + (t - t0) / ((t1 - t0) || 1) * (W - L - R);
  const svg = sv("svg", { id: "gantt", viewBox: `0 0 ${W} ${H}`, width: "100%" });
  const day = 864e5, every = (t1 - t0) > 40 * day ? 7 * day : (t1 - t0) > 10 * day ? 2 * day : day;
  for (let t = Math.ceil(t0 / day) * day; t <= t1; t += every) {
    svg.append(sv("line", { x1: X(t), x2: X(t), y1: T - 6, y2: H, stroke: "#d0d8df" }),
      sv("text", { x: X(t) + 2, y: T - 10, "font-size": 11, fill: "#334" }, new Date(t).toISOString().slice(5, 10)));
  }
  d.rows.forEach((row, i) => {
    const y = T + i * rowH;
    svg.append(sv("rect", { x: 0, y, width: W, height: rowH, fill: i % 2 ? "#f3f6f8" : "#fff" }),
      sv("text", { x: 6, y: y + rowH / 2 + 4, "font-size": 12, "font-weight": 600 }, row.name + (row.legs.length ? "" : " (idle)")));
    for (const l of row.legs) {
      const x0 = X(Date.parse(l.depart_utc)), x1 = X(Date.parse(l.arrive_utc));
      const laden = l.kind === "laden";
      const bar = sv("rect", { class: `gantt-bar ${l.kind}`, "data-voyage": l.voyage_id || "", x: x0, y: y + 7, width: Math.max(2, x1 - x0), height: rowH - 14, rx: 3,
        fill: laden ? "#2f6fa8" : "#c7d0d8", stroke: STATUS_COLOUR[l.voyage_status] || "#6b7884", "stroke-width": l.voyage_status ? 2 : 1 },
        title(`${l.kind} ${l.contract_code || ""} ${l.from_port} → ${l.to_port}, ${utc(l.depart_utc)} – ${utc(l.arrive_utc)}, ${num(l.dist_nm, 0)} NM, ${num(l.fuel_t)} t` + (l.voyage_status ? ` · voyage ${l.voyage_id}: ${l.voyage_status}, ETA ${utc(l.voyage_eta_utc)}` : "")));
      svg.append(l.voyage_id ? (() => { const a = sv("a", { href: `/voyage/${encodeURIComponent(l.voyage_id)}` }); a.append(bar); return a; })() : bar);
      const text = `${laden ? l.contract_code + " " : ""}${l.from_port}→${l.to_port}`;
      if (x1 - x0 > 6 * text.length + 8) svg.append(sv("text", { x: x0 + 4, y: y + rowH / 2 + 4, "font-size": 10, fill: laden ? "#fff" : "#223" }, text));
    }
  });
  main.append(el("div", { cls: "chart" }, svg), el("div", { cls: "legend" }, swatch("#2f6fa8"), "laden (contract)", swatch("#c7d0d8"), "ballast", " · bar outline: what the voyage became (green on time, orange late)"));
  const legs = d.rows.flatMap(r => r.legs.map(l => ({ ...l, name: r.name })));
  main.append(el("h2", { text: "Legs and what each voyage became" }), table(
    ["Vessel", "Kind", "Contract", "From", "To", "Depart (UTC)", "Arrive by (UTC)", "Dist NM ", "Fuel t ", "Voyage", "Became", "Voyage ETA (UTC)"],
    legs.map(l => el("tr", {}, td(l.name), td(l.kind), td(l.contract_code), td(l.from_port), td(l.to_port), td(utc(l.depart_utc)), td(utc(l.arrive_utc)),
      td(num(l.dist_nm, 0), "num"), td(num(l.fuel_t), "num"), el("td", {}, l.voyage_id ? el("a", { href: `/voyage/${encodeURIComponent(l.voyage_id)}`, text: l.voyage_id }) : "–"),
      l.voyage_status ? statusCell(l.voyage_status) : td(l.voyage_id ? "not routed yet" : "–"), td(utc(l.voyage_eta_utc)))), "plan-legs"));
  main.append(el("h2", { text: `Contracts left (${d.unassigned.length})` }), d.unassigned.length ? table(["Contract", "Penalty ", "Why"],
    d.unassigned.map(u => el("tr", {}, td(u.contract_code), td(num(u.penalty, 0), "num"), el("td", { cls: "wrap", text: u.reason }))), "unassigned") : el("p", { text: "none" }));
}

/* ---- Runs ---- */
async function runsPage(main) {
  const d = await getJSON("/api/runs");
  main.replaceChildren(el("h1", { text: "Runs" }), el("p", { cls: "summary", text: `data root ${d.data_root}` }));
  main.append(el("h2", { text: "Routing runs (newest first)" }), table(
    ["Started (UTC)", "Run", "Trigger", "Status", "Cycle", "Cycle age h ", "Voyages ", "On time ", "Late ", "Not routed ", "Exports failed ", "Saving % ", "profile % ", "route % ", "in forecast % ", "P10–P90 % ", "Verified ", "claimed % ", "realised % ", "Compared ", "Reason"],
    d.runs.map(r => el("tr", {}, td(utc(r.started_at)), td(r.run_id), td(r.trigger), statusCell(r.status), td(utc(r.cycle)), td(num(r.cycle_age_h, 0), "num"),
      td(r.n_voyages, "num"), td(r.n_on_time, "num"), td(r.n_late, "num"), td(r.n_not_routed, "num"), td(r.n_export_failed, "num"),
      td(num(r.savings_total_pct, 2), "num"), td(num(r.savings_speed_profile_pct, 2), "num"), td(num(r.savings_route_pct, 2), "num"),
      td(num(r.savings_forecast_pct, 2), "num"), td(r.savings_p10_pct == null ? "–" : `${num(r.savings_p10_pct, 1)} to ${num(r.savings_p90_pct, 1)}`, "num"),
      td(r.n_verified || "–", "num"), td(num(r.verified_claimed_savings_pct, 2), "num"), td(num(r.realised_savings_pct, 2), "num"), td(r.n_compared, "num"),
      el("td", { cls: "wrap", text: [r.reason, r.export_errors].filter(Boolean).join("; ") }))), "runs"),
    el("p", { cls: "note", text: "Saving: fuel saved against the same voyages sailed at the one constant speed that arrives at the RTA in the same weather (each run solves that baseline itself), fuel-weighted over the voyages compared; split into the speed profile on the base route and the route; \"in forecast\": the part of the saving made before the forecast's last valid time (past it every route sails the same neutral weather); P10–P90: the saving across the lagged ensemble. Verified: plans re-sailed in the analysed weather of later cycles (jitroute verify, the nightly); claimed and realised are over those same plans. What was actually burnt is on each voyage's page (plan against noon reports)." }));
  main.append(el("h2", { text: "Weather cycles" }), table(["Cycle (UTC)", "Complete", "Files ok ", "Expected ", "Missing", "Written (UTC)"],
    d.cycles.map(c => el("tr", {}, td(utc(c.cycle)), td(c.complete ? "yes" : "NO", c.complete ? "status-ok" : "status-failed"), td(c.n_files_ok, "num"), td(c.n_files_expected, "num"),
      el("td", { cls: "wrap", text: c.missing || "" }), td(utc(c.written_at)))), "cycles"));
  main.append(el("h2", { text: `Ingest failures (${d.ingest_failures.length})` }), d.ingest_failures.length ? table(["When (UTC)", "Source", "Cycle", "File", "Status", "Error"],
    d.ingest_failures.map(f => el("tr", {}, td(utc(f.started_at)), td(f.source), td(utc(f.cycle)), td(f.file_name), statusCell(f.status), el("td", { cls: "wrap", text: f.error || "" }))), "ingest-failures")
    : el("p", { text: "none" }));
}

function route() {
  const path = location.pathname, main = document.getElementById("main");
  const page = path.startsWith("/voyage/") ? "voyage" : path.replace(/^\//, "") || "fleet";
  for (const a of document.querySelectorAll("header nav a")) a.classList.toggle("active", a.dataset.page === page);
  document.body.dataset.page = page;
  const done = () => document.body.setAttribute("data-ready", "1");
  const run = page === "voyage" ? voyagePage(main, decodeURIComponent(path.slice("/voyage/".length)))
    : page === "plan" ? planPage(main) : page === "runs" ? runsPage(main) : fleetPage(main);
  run.then(done, err => { fail(err); done(); });
}
route();
