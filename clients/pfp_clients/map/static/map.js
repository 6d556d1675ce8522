// pfp map: the page.  It draws what the server pushes over /ws (a snapshot, then deltas at
// a bounded rate) and talks to the mission only through the server's small HTTP API.
// Positions arrive in mission metres (x east, y north); toLatLng() is the one place that
// maps them onto the Leaflet map: CRS.Simple in metres, or lat/lon around the origin.
"use strict";

const STATUS_COLOURS = {
  en_route: "#2e7d32",
  escaping: "#f9a825",
  arrived: "#1565c0",
  trapped: "#c62828",
  no_goal: "#8e24aa",
  unknown: "#546e7a",
  stale: "#9e9e9e",
};
const TRACK_MAX = 200;
const DOTS_MAX_UNITS = 200; // above this many units only the selected one shows its look-ahead points
const CULL_MIN_UNITS = 200; // above this many units, those far outside the view are drawn when it gets there
const EVENTS_SHOWN = 60;

const state = {
  config: null,
  map: null,
  offset: 0, // server clock minus ours, seconds
  units: new Map(), // id -> {data, marker, track, look, goal}
  threats: new Map(), // id -> {data, layers, label}
  zones: new Map(), // id -> {data, layer}: keep-out zones
  selectedZone: null,
  draft: [], // the corners (metres) of a keep-out zone being drawn; a circle's centre
  draftLayer: null,
  rejected: new Map(),
  selectedUnit: null,
  selectedThreat: null,
  mode: null, // null | "drop-threat" | "move-threat" | "set-goal" | "zone-polygon" | "zone-centre" | "zone-edge"
  fitted: false,
  perf: { frames: 0, bytes: 0, applyMsTotal: 0, applyMsMax: 0 }, // what each frame costs the page
  userMoved: false, // the operator panned or zoomed: stop following
  frame: null, // the ENU frame of the origin, or null for plain metres
  preview: null,
  dropCount: 0,
};
window.pfpMap = state; // for tests and the curious: read-only by convention
state.state_now = () => serverNow(); // the server's clock, as the page estimates it

const $ = (id) => document.getElementById(id);
const serverNow = () => Date.now() / 1000 + state.offset;
const fmt = (v, digits = 1) => (v === null || v === undefined ? "–" : Number(v).toFixed(digits));
const esc = (s) => String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));

function ageText(seconds) {
  if (seconds === null || seconds === undefined || !isFinite(seconds)) return "–";
  if (seconds < 60) return `${Math.max(0, Math.round(seconds))} s`;
  if (seconds < 3600) return `${Math.floor(seconds / 60)} min ${Math.round(seconds % 60)} s`;
  return `${(seconds / 3600).toFixed(1)} h`;
}

// -- frames ----------------------------------------------------------------------------
// With an origin, mission metres are east/north on the WGS-84 ENU plane at the origin's
// height, exactly as pfp_service/geo.py (pymap3d) defines them: geodetic -> ECEF -> ENU,
// the up component dropped; the inverse finds the point of the plane's height with that
// (e, n) by fixed-point passes on u.
const WGS84_A = 6378137.0;
const WGS84_F = 1 / 298.257223563;
const WGS84_E2 = WGS84_F * (2 - WGS84_F);
const RAD = Math.PI / 180;

function geodeticToEcef(latDeg, lonDeg, h) {
  const lat = latDeg * RAD, lon = lonDeg * RAD;
  const s = Math.sin(lat), c = Math.cos(lat);
  const n = WGS84_A / Math.sqrt(1 - WGS84_E2 * s * s);
  return [(n + h) * c * Math.cos(lon), (n + h) * c * Math.sin(lon), (n * (1 - WGS84_E2) + h) * s];
}

function ecefToGeodetic(x, y, z) {
  const lon = Math.atan2(y, x);
  const p = Math.hypot(x, y);
  let lat = Math.atan2(z, p * (1 - WGS84_E2));
  let h = 0;
  for (let i = 0; i < 8; i++) {
    const s = Math.sin(lat);
    const n = WGS84_A / Math.sqrt(1 - WGS84_E2 * s * s);
    h = p / Math.cos(lat) - n;
    lat = Math.atan2(z, p * (1 - (WGS84_E2 * n) / (n + h)));
  }
  return [lat / RAD, lon / RAD, h];
}

function frame(o) {
  const lat = o.lat * RAD, lon = o.lon * RAD;
  return { o, sl: Math.sin(lat), cl: Math.cos(lat), so: Math.sin(lon), co: Math.cos(lon), p0: geodeticToEcef(o.lat, o.lon, o.alt) };
}

function geodeticToEnu(f, latDeg, lonDeg, h) {
  const [x, y, z] = geodeticToEcef(latDeg, lonDeg, h);
  const dx = x - f.p0[0], dy = y - f.p0[1], dz = z - f.p0[2];
  return [
    -f.so * dx + f.co * dy,
    -f.sl * f.co * dx - f.sl * f.so * dy + f.cl * dz,
    f.cl * f.co * dx + f.cl * f.so * dy + f.sl * dz,
  ];
}

function enuToGeodetic(f, e, n, u) {
  const dx = -f.so * e - f.sl * f.co * n + f.cl * f.co * u;
  const dy = f.co * e - f.sl * f.so * n + f.cl * f.so * u;
  const dz = f.cl * n + f.sl * u;
  return ecefToGeodetic(f.p0[0] + dx, f.p0[1] + dy, f.p0[2] + dz);
}

function toLatLng(p) {
  const f = state.frame;
  if (!f) return L.latLng(p[1], p[0]);
  let u = 0;
  for (let i = 0; i < 3; i++) {
    const [lat, lon] = enuToGeodetic(f, p[0], p[1], u);
    u = geodeticToEnu(f, lat, lon, f.o.alt)[2];
  }
  const [lat, lon] = enuToGeodetic(f, p[0], p[1], u);
  return L.latLng(lat, ((lon + 540) % 360) - 180);
}

function toMetres(ll) {
  const f = state.frame;
  if (!f) return [ll.lng, ll.lat];
  const [e, n] = geodeticToEnu(f, ll.lat, ll.lng, f.o.alt);
  return [e, n];
}

function createMap(config) {
  state.config = config;
  state.frame = config.origin ? frame(config.origin) : null;
  const geo = !!config.origin;
  const map = L.map("map", {
    crs: geo ? L.CRS.EPSG3857 : L.CRS.Simple,
    minZoom: geo ? 2 : -5,
    maxZoom: geo ? 22 : 8,
    zoomSnap: 0.25,
    preferCanvas: true,
    attributionControl: !!config.tiles,
  });
  if (geo && config.tiles) {
    L.tileLayer(config.tiles, { maxZoom: 22, attribution: "offline tiles" }).addTo(map);
  }
  if (geo) map.setView(toLatLng([0, 0]), 17);
  else map.setView([0, 0], 2);
  L.control.scale({ imperial: false, metric: true }).addTo(map);
  state.layers = {
    zones: L.layerGroup().addTo(map),
    threats: L.layerGroup().addTo(map),
    tracks: L.layerGroup().addTo(map),
    look: L.layerGroup().addTo(map),
    goals: L.layerGroup().addTo(map),
    preview: L.layerGroup().addTo(map),
    units: L.layerGroup().addTo(map),
  };
  state.renderer = L.canvas({ padding: 0.2 });
  map.on("click", onMapClick);
  map.on("dblclick", () => state.mode === "zone-polygon" && finishPolygon());
  map.on("moveend", () => {
    const view = map.getBounds().pad(0.3);
    state.units.forEach((u) => {
      if (u.offscreen && u.data.position) {
        const ll = toLatLng(u.data.position);
        if (view.contains(ll)) drawUnit(u, ll);
      }
    });
  });
  const moved = () => (state.userMoved = true);
  map.on("dragstart", moved);
  map.getContainer().addEventListener("wheel", moved, { passive: true });
  map.getContainer().addEventListener("dblclick", moved);
  map.zoomControl.getContainer().addEventListener("click", moved);
  map.on("mousemove", (e) => {
    const [x, y] = toMetres(e.latlng);
    if (state.draft.length && (state.mode === "zone-polygon" || state.mode === "zone-edge")) drawDraft([x, y]);
    $("cursor").textContent = `x ${x.toFixed(1)} m, y ${y.toFixed(1)} m` + (geo ? `  (${e.latlng.lat.toFixed(6)}, ${e.latlng.lng.toFixed(6)})` : "");
  });
  state.map = map;
  $("mission").textContent = `mission ${config.mission}` + (geo ? ` · origin ${config.origin.lat}, ${config.origin.lon}` : " · metres (no origin)");
  document.querySelectorAll(".edit-only").forEach((el) => (el.hidden = !config.allow_edit));
  $("legend").innerHTML =
    Object.entries(STATUS_COLOURS)
      .map(([k, c]) => `<span class="sw" style="background:${c}"></span>${k.replace("_", " ")}`)
      .join("") + ` &nbsp; ● manned ◆ unmanned`;
  pfpTerrain.start(config, map);
}

// -- units --------------------------------------------------------------------------------
function unitColour(d) {
  if (d.stale) return STATUS_COLOURS.stale;
  return STATUS_COLOURS[d.status] || STATUS_COLOURS.unknown;
}

function unitSvg(d) {
  const body =
    d.kind === "unmanned"
      ? `<rect class="body" x="-7" y="-7" width="14" height="14" transform="rotate(45)" />`
      : `<circle class="body" r="8" />`;
  return (
    `<svg width="24" height="24" viewBox="-12 -12 24 24">` +
    `<g class="arrow"><line x1="0" y1="0" x2="0" y2="-24" stroke="#111" stroke-width="2.5"/>` +
    `<path d="M -5 -21 L 0 -30 L 5 -21 Z" fill="#111"/></g>` +
    `<g class="shape" stroke="#fff" stroke-width="2">${body}</g></svg><span class="label"></span>`
  );
}

// Only what changed touches the DOM or the canvas: a thousand units at 5 frames a second.
function setAttr(el, name, value, cache, key) {
  if (cache[key] === value) return;
  cache[key] = value;
  el.setAttribute(name, value);
}

function paintUnit(u) {
  const d = u.data;
  const dom = u.dom;
  if (!dom) return;
  const c = u.painted;
  const status = d.stale ? "stale" : d.status || "unknown";
  const selected = state.selectedUnit === d.id;
  if (c.status !== status) {
    c.status = status;
    dom.el.dataset.status = status;
    dom.el.classList.toggle("stale", !!d.stale);
  }
  if (c.selected !== selected) {
    c.selected = selected;
    dom.el.classList.toggle("selected", selected);
  }
  if (c.kind !== (d.kind || "")) dom.el.dataset.kind = c.kind = d.kind || "";
  setAttr(dom.shape, "fill", unitColour(d), c, "fill");
  setAttr(dom.shape, "opacity", d.stale ? "0.55" : "1", c, "opacity");
  const hidden = d.heading_deg === null || d.heading_deg === undefined || d.stale;
  setAttr(dom.arrow, "visibility", hidden ? "hidden" : "visible", c, "visibility");
  if (!hidden) setAttr(dom.arrow, "transform", `rotate(${Math.round(d.heading_deg)})`, c, "transform");
  const age = d.last_seen === null || d.last_seen === undefined ? null : serverNow() - d.last_seen;
  const label = d.stale ? `${d.id} · ${ageText(age)}` : d.id;
  if (c.label !== label) dom.label.textContent = c.label = label;
}

function upsertUnit(d, full) {
  let u = state.units.get(d.id);
  if (!u) {
    u = { data: d, marker: null, dom: null, painted: {}, track: null, trackLL: [], look: null, lookDots: [], goal: null, colour: null };
    state.units.set(d.id, u);
  }
  const goalMoved = JSON.stringify(u.data.goal) !== JSON.stringify(d.goal);
  u.data = d;
  if (goalMoved && state.selectedUnit === d.id) schedulePreview();
  let trackMoved = false;
  if (full) {
    u.trackLL = (d.track || []).slice(-TRACK_MAX).map(toLatLng);
    trackMoved = true;
  } else if (d.track_add && d.track_add.length) {
    for (const p of d.track_add) u.trackLL.push(toLatLng(p));
    if (u.trackLL.length > TRACK_MAX) u.trackLL.splice(0, u.trackLL.length - TRACK_MAX);
    trackMoved = true;
  }
  if (!d.position) return; // heard of (a token, a direction) but never seen: nothing to draw yet
  u.trackMoved = u.trackMoved || trackMoved;
  u.goalMoved = u.goalMoved || goalMoved;
  const ll = toLatLng(d.position);
  // in a big mission, a unit far outside the view waits until the view comes to it
  if (u.marker && state.cull && !state.cull.contains(ll) && state.selectedUnit !== d.id) {
    u.offscreen = true;
    return;
  }
  drawUnit(u, ll);
}

function drawUnit(u, ll) {
  const d = u.data;
  const trackMoved = u.trackMoved;
  const goalMoved = u.goalMoved;
  u.trackMoved = u.goalMoved = u.offscreen = false;
  if (!u.marker) {
    const icon = L.divIcon({ className: "unit-icon", html: unitSvg(d), iconSize: [24, 24], iconAnchor: [12, 12] });
    u.marker = L.marker(ll, { icon, keyboard: false, riseOnHover: true }).addTo(state.layers.units);
    u.marker.on("click", (e) => {
      L.DomEvent.stopPropagation(e);
      selectUnit(d.id);
    });
    const el = u.marker.getElement();
    el.dataset.unit = d.id;
    u.dom = { el, shape: el.querySelector(".shape"), arrow: el.querySelector(".arrow"), label: el.querySelector(".label") };
  } else {
    u.marker.setLatLng(ll);
  }
  const colour = unitColour(d);
  const recoloured = colour !== u.colour;
  u.colour = colour;
  if (!u.track) u.track = L.polyline(u.trackLL, { color: colour, weight: 2, opacity: 0.6, renderer: state.renderer, interactive: false }).addTo(state.layers.tracks);
  else {
    if (trackMoved) u.track.setLatLngs(u.trackLL);
    if (recoloured) u.track.setStyle({ color: colour });
  }
  const ahead = d.stale ? [] : (d.lookahead || []).map(toLatLng);
  const lookLL = ahead.length ? [ll, ...ahead] : [];
  if (!u.look) u.look = L.polyline(lookLL, { color: colour, weight: 2, dashArray: "3 4", opacity: 0.9, renderer: state.renderer, interactive: false }).addTo(state.layers.look);
  else {
    u.look.setLatLngs(lookLL);
    if (recoloured) u.look.setStyle({ color: colour });
  }
  // the points themselves: for every unit in a small mission, for the selected one in a big one
  const dots = state.units.size <= DOTS_MAX_UNITS || state.selectedUnit === d.id ? ahead : [];
  while (u.lookDots.length > dots.length) state.layers.look.removeLayer(u.lookDots.pop());
  dots.forEach((p, i) => {
    if (i < u.lookDots.length) {
      u.lookDots[i].setLatLng(p);
      if (recoloured) u.lookDots[i].setStyle({ color: colour });
    } else u.lookDots.push(L.circleMarker(p, { radius: 2, color: colour, weight: 1, fillOpacity: 1, renderer: state.renderer, interactive: false }).addTo(state.layers.look));
  });
  if (d.goal) {
    const gl = toLatLng(d.goal);
    if (!u.goal) u.goal = L.circleMarker(gl, { radius: 5, color: "#000", weight: 2, fill: false, renderer: state.renderer }).bindTooltip(`goal of ${esc(d.id)}`).addTo(state.layers.goals);
    else if (goalMoved) u.goal.setLatLng(gl);
  } else if (u.goal) {
    state.layers.goals.removeLayer(u.goal);
    u.goal = null;
  }
  paintUnit(u);
  if (state.selectedUnit === d.id) showUnit();
}

function removeUnit(id) {
  const u = state.units.get(id);
  if (!u) return;
  if (u.marker) state.layers.units.removeLayer(u.marker);
  if (u.track) state.layers.tracks.removeLayer(u.track);
  if (u.look) state.layers.look.removeLayer(u.look);
  u.lookDots.forEach((m) => state.layers.look.removeLayer(m));
  if (u.goal) state.layers.goals.removeLayer(u.goal);
  state.units.delete(id);
  if (state.selectedUnit === id) closeUnit();
}

// -- threats --------------------------------------------------------------------------------
function upsertThreat(d) {
  removeThreat(d.id, true);
  const pos = d.position;
  const zone = L.polygon(d.zone.map(toLatLng), { color: "#d32f2f", weight: 1, dashArray: "4 3", fillColor: "#e53935", fillOpacity: 0.1 });
  const layers = [zone];
  if (d.core && d.core.length) layers.push(L.polygon(d.core.map(toLatLng), { color: "#b71c1c", weight: 1, fillColor: "#b71c1c", fillOpacity: 0.35 }));
  // the shape's own marks (a skew-normal's facing arrow), drawn as given: the page knows no shape's parameters
  (d.marks || []).forEach((line) => layers.push(L.polyline(line.map(toLatLng), { color: "#4a0000", weight: 2 })));
  const centre = L.circleMarker(toLatLng(pos), { radius: 4, color: "#4a0000", weight: 1, fillColor: "#fff", fillOpacity: 1 });
  layers.push(centre);
  centre.bindTooltip("", { permanent: true, direction: "right", offset: [6, 0], className: "threat-label" });
  layers.forEach((l) => {
    l.addTo(state.layers.threats);
    l.on("click", (e) => {
      L.DomEvent.stopPropagation(e);
      selectThreat(d.id);
    });
  });
  state.threats.set(d.id, { data: d, layers, centre });
  paintThreat(state.threats.get(d.id));
  if (state.selectedThreat === d.id) {
    showThreat();
    pfpTerrain.threatSelected(d.id); // moved: its viewshed again
  }
}

function threatTtl(d) {
  return d.expires_at === null || d.expires_at === undefined ? null : d.expires_at - serverNow();
}

function paintThreat(t) {
  const ttl = threatTtl(t.data);
  const text = ttl === null ? t.data.id : `${t.data.id} · ${ageText(Math.max(0, ttl))}`;
  t.centre.setTooltipContent(esc(text));
}

function removeThreat(id, replacing) {
  const t = state.threats.get(id);
  if (!t) return;
  t.layers.forEach((l) => state.layers.threats.removeLayer(l));
  state.threats.delete(id);
  if (!replacing && state.selectedThreat === id) closeThreat();
}

// -- keep-out zones: no unit's path enters one; drawn black, hatched dark, named "no-go" ------------
function upsertZone(d) {
  removeZone(d.id, true);
  const style = { color: "#111", weight: 2, fillColor: "#37474f", fillOpacity: 0.45 };
  const layer = d.circle
    ? L.circle(toLatLng(d.circle.centre), Object.assign({ radius: d.circle.radius_m }, style))
    : L.polygon(d.polygon.map((ring) => ring.slice(0, -1).map(toLatLng)), style);
  // labelled always, not only on hover: an operator reads which zone a unit bends round at a glance
  layer.bindTooltip(`no-go ${esc(d.id)}`, { permanent: true, direction: "center", className: "zone-label" });
  layer.on("click", (e) => {
    L.DomEvent.stopPropagation(e);
    selectZone(d.id);
  });
  layer.addTo(state.layers.zones);
  state.zones.set(d.id, { data: d, layer });
  if (state.selectedZone === d.id) showZone();
}

function removeZone(id, replacing) {
  const z = state.zones.get(id);
  if (!z) return;
  state.layers.zones.removeLayer(z.layer);
  state.zones.delete(id);
  if (!replacing && state.selectedZone === id) closeZone();
}

function zonePoints(d) {
  if (d.circle) {
    const [x, y] = d.circle.centre;
    const r = d.circle.radius_m;
    return [[x - r, y - r], [x + r, y + r]];
  }
  return d.polygon[0];
}

function showZone() {
  const z = state.zones.get(state.selectedZone);
  if (!z) return;
  const d = z.data;
  $("zone-panel").hidden = false;
  $("zone-id").textContent = d.id;
  const ttl = threatTtl(d);
  const shape = d.circle
    ? row("circle", `centre ${fmt(d.circle.centre[0])}, ${fmt(d.circle.centre[1])} m, radius ${fmt(d.circle.radius_m)} m`)
    : row("polygon", `${d.polygon[0].length - 1} corners` + (d.polygon.length > 1 ? `, ${d.polygon.length - 1} hole(s)` : ""));
  $("zone-info").innerHTML = row("kind", esc(d.kind)) + shape + row("TTL left", ttl === null ? "none (until deleted)" : ageText(Math.max(0, ttl)));
}

function selectZone(id) {
  if (state.selectedUnit) closeUnit();
  if (state.selectedThreat) closeThreat();
  state.selectedZone = id;
  showZone();
}

function closeZone() {
  state.selectedZone = null;
  $("zone-panel").hidden = true;
}

function newZoneId() {
  const given = $("new-id").value.trim();
  if (given) return given;
  let id;
  do id = `map-zone-${++state.dropCount}`;
  while (state.zones.has(id));
  return id;
}

function drawDraft(cursor) {
  if (state.draftLayer) state.map.removeLayer(state.draftLayer);
  state.draftLayer = null;
  const pts = state.draft.map(toLatLng);
  if (state.mode === "zone-edge" && cursor) {
    const r = Math.hypot(cursor[0] - state.draft[0][0], cursor[1] - state.draft[0][1]);
    state.draftLayer = L.circle(pts[0], { radius: r, color: "#111", dashArray: "4 3", weight: 2, fill: false });
  } else if (pts.length) {
    state.draftLayer = L.polyline(cursor ? [...pts, toLatLng(cursor)] : pts, { color: "#111", dashArray: "4 3", weight: 2 });
  }
  if (state.draftLayer) state.draftLayer.addTo(state.map);
}

function endDraft() {
  state.draft = [];
  drawDraft(null);
  $("zone-finish").hidden = true;
  $("zone-cancel").hidden = true;
}

function startZone(mode) {
  endDraft();
  setMode(mode);
  $("zone-cancel").hidden = false;
}

async function finishPolygon() {
  const ring = state.draft.slice();
  if (ring.length < 3) {
    $("edit-result").textContent = "a keep-out polygon needs at least 3 corners";
    return;
  }
  setMode(null);
  endDraft();
  await edit("PUT", `/api/zone/${encodeURIComponent(newZoneId())}`, { kind: "keep_out", polygon: [[...ring, ring[0]]] });
}

// -- panels ------------------------------------------------------------------------------------
function renderStatus(all) {
  const rows = Object.values(all).map((s) => {
    const age = serverNow() - s.received_at;
    const cls = age > 5 ? "planner stale-status" : "planner";
    return (
      `<div class="${cls}"><b>${esc(s.planner)}</b> ${s.version ? esc(s.version) : ""} · up ${ageText(s.uptime_s)}` +
      (age > 5 ? ` · <b>silent ${ageText(age)}</b>` : "") +
      `<table><tr><td>units</td><td>${s.units} (${s.units_stale} stale)</td><td>threats</td><td>${s.threats}</td></tr>` +
      `<tr><td>latency</td><td colspan="3">p50 ${fmt(s.latency_p50_ms, 2)} ms · p99 ${fmt(s.latency_p99_ms, 2)} ms</td></tr>` +
      `<tr><td>msgs</td><td colspan="3">in ${s.msgs_in} · out ${s.msgs_out} · rejected ${s.rejected}</td></tr></table></div>`
    );
  });
  $("status").innerHTML = rows.length ? rows.join("") : "no planner has answered yet";
}

function clock(t) {
  return new Date(t * 1000).toLocaleTimeString([], { hour12: false });
}

function eventText(e) {
  switch (e.kind) {
    case "replan": {
      const changes = (e.changes || []).map((c) => `${c.threat} ${c.change}`).join(", ");
      const n = e.units.length + (e.more_units || 0);
      return `replan: ${changes || esc(e.reason)}; ${n} unit${n === 1 ? "" : "s"} redirected`;
    }
    case "trapped":
      return `${e.unit} trapped at (${fmt(e.position[0])}, ${fmt(e.position[1])})${e.reason ? ": " + e.reason : ""}`;
    case "arrived":
      return `${e.unit} arrived (${fmt(e.distance_to_goal, 2)} m from goal)`;
    case "stale":
      return `${e.unit} stale${e.reason ? ": " + e.reason : ""}`;
    case "forgotten":
      return `${e.unit} forgotten after ${ageText(e.stale_s)} stale`;
    default:
      return `${e.kind}`;
  }
}

function addEvents(list) {
  const ul = $("events");
  for (const e of list) {
    const li = document.createElement("li");
    li.className = `ev-${e.kind}`;
    li.innerHTML = `<span class="t">${clock(e.t)}</span>${esc(eventText(e))}`;
    ul.prepend(li);
  }
  while (ul.children.length > EVENTS_SHOWN) ul.lastChild.remove();
}

function renderRejected() {
  const items = [...state.rejected.values()].sort((a, b) => b.last_t - a.last_t);
  $("rejected").innerHTML = items
    .map(
      (r) =>
        `<li data-count="${r.count}"><span class="t">${clock(r.last_t)}</span>rejected ×${r.count}: ` +
        `${esc(r.key_kind)} ${esc(r.field)}: ${esc(r.reason)} <span class="t">(last ${esc(r.last_key || "")})</span></li>`
    )
    .join("");
}

function row(k, v) {
  return `<tr><td>${esc(k)}</td><td>${v}</td></tr>`;
}

// what a direction's route and progress mean, in words (docs/wire.md's statuses)
const ROUTE_WORDS = {
  descent: "the foreseen descent",
  lower_exposure: "round the threats, for lower exposure",
  around_trap: "round a trap ahead",
  escape: "out of a trap met",
  leave: "out of a core or zone",
};
const PROGRESS_WORDS = {
  moving: "moving",
  holding: "holding (the unit says it is stopped)",
  stalled: "stalled: told to move, it has not moved for 10 s",
};

function showUnit() {
  const u = state.units.get(state.selectedUnit);
  if (!u) return;
  const d = u.data;
  $("unit-panel").hidden = false;
  $("unit-id").textContent = d.id;
  const age = d.last_seen === null || d.last_seen === undefined ? null : serverNow() - d.last_seen;
  $("unit-info").innerHTML =
    row("kind", esc(d.kind || "?")) +
    row("status", `<span style="color:${unitColour(d)}">■</span> ${esc(d.stale ? "stale" : d.status || "no direction yet")}`) +
    (d.reason ? row("reason", esc(d.reason)) : "") +
    (d.route ? row("route", esc(ROUTE_WORDS[d.route] || d.route)) : "") +
    (d.progress ? row("progress", esc(PROGRESS_WORDS[d.progress] || d.progress)) : "") +
    row("position", d.position ? `${fmt(d.position[0])}, ${fmt(d.position[1])} m` : "–") +
    row("heading", d.heading_deg === null ? "–" : `${fmt(d.heading_deg, 0)}°`) +
    row("speed", d.speed_mps === null ? "–" : `${fmt(d.speed_mps)} m/s`) +
    row("to goal", d.distance_to_goal === null ? "–" : `${fmt(d.distance_to_goal)} m`) +
    row("threat level", fmt(d.threat_level, 3)) +
    row("last report", age === null ? "never" : `${ageText(age)} ago`);
}

function showPreview(body) {
  state.layers.preview.clearLayers();
  state.preview = body;
  const el = $("preview");
  if (body.error) {
    el.innerHTML = `<span class="err">${esc(body.error)}</span>`;
    el.dataset.state = "error";
    return;
  }
  const p = body.preview;
  el.dataset.state = "ok";
  el.innerHTML =
    `<table>` +
    row("status", esc(p.status)) +
    row("reason", esc(p.reason || "–")) +
    row("length", `${fmt(p.length)} m`) +
    row("exposure", fmt(p.exposure, 3)) +
    row("min clearance", p.min_clearance === null ? "no threat" : `${fmt(p.min_clearance, 2)} m`) +
    (p.min_zone_clearance === null || p.min_zone_clearance === undefined ? "" : row("zone clearance", `${fmt(p.min_zone_clearance, 2)} m`)) +
    row("ETA", p.eta_s === null ? "unknown speed" : `${ageText(p.eta_s)} at ${fmt(p.speed_mps)} m/s`) +
    row("steps", `${p.steps} (${fmt(p.compute_ms, 0)} ms)`) +
    (p.escapes && p.escapes.length ? row("escapes", esc(p.escapes.join(", "))) : "") +
    `</table>`;
  if (p.path && p.path.length > 1) {
    L.polyline(p.path.map(toLatLng), { color: "#0d47a1", weight: 4, opacity: 0.75, dashArray: "8 6", interactive: false }).addTo(state.layers.preview);
  }
}

async function fetchPreview() {
  const id = state.selectedUnit;
  if (!id) return;
  state.previewAt = Date.now();
  $("preview").textContent = "asking the planner…";
  $("preview").dataset.state = "pending";
  try {
    const r = await fetch(`/api/preview/${encodeURIComponent(id)}`);
    const body = await r.json();
    if (state.selectedUnit === id) showPreview(body);
  } catch (err) {
    if (state.selectedUnit === id) showPreview({ error: `map server unreachable (${err})` });
  }
}

// The selected unit's preview is asked again when its goal or its threats change, at most every 2 s.
function schedulePreview() {
  if (state.previewTimer) return;
  const wait = Math.max(0, 2000 - (Date.now() - (state.previewAt || 0)));
  state.previewTimer = setTimeout(() => {
    state.previewTimer = null;
    fetchPreview();
  }, wait);
}

function selectUnit(id) {
  closeThreat();
  const prev = state.units.get(state.selectedUnit);
  state.selectedUnit = id;
  if (prev) paintUnit(prev);
  const u = state.units.get(id);
  if (u) paintUnit(u);
  showUnit();
  fetchPreview();
}

function closeUnit() {
  const prev = state.units.get(state.selectedUnit);
  state.selectedUnit = null;
  if (prev) paintUnit(prev);
  $("unit-panel").hidden = true;
  state.layers.preview.clearLayers();
  if (state.mode === "set-goal") setMode(null);
}

function showThreat() {
  const t = state.threats.get(state.selectedThreat);
  if (!t) return;
  const d = t.data;
  $("threat-panel").hidden = false;
  $("threat-id").textContent = d.id;
  const ttl = threatTtl(d);
  $("threat-info").innerHTML =
    row("position", `${fmt(d.position[0])}, ${fmt(d.position[1])} m`) +
    (d.rows || []).map(([label, value]) => row(label, esc(value))).join("") +
    row("weight", fmt(d.weight, 2)) +
    row("TTL left", ttl === null ? "none (until deleted)" : ageText(Math.max(0, ttl)));
}

function selectThreat(id) {
  if (state.selectedUnit) closeUnit();
  state.selectedThreat = id;
  showThreat();
  pfpTerrain.threatSelected(id);
}

function closeThreat() {
  state.selectedThreat = null;
  $("threat-panel").hidden = true;
  pfpTerrain.threatClosed();
  if (state.mode === "move-threat") setMode(null);
}

// -- editing: every edit is one put or delete on the mission's keys, through the server -----------
function setMode(mode) {
  state.mode = mode;
  const text = {
    "drop-threat": "click the map to drop a threat",
    "move-threat": "click the map to move the threat",
    "set-goal": "click the map to set the goal",
    "zone-polygon": "click the zone's corners, then finish (or double-click)",
    "zone-centre": "click the circle's centre",
    "zone-edge": "click the circle's edge",
  }[mode];
  $("edit-mode").textContent = text || "";
  if (state.map) {
    state.map.getContainer().classList.toggle("edit-mode", !!mode);
    if (mode === "zone-polygon") state.map.doubleClickZoom.disable(); // a double-click finishes the polygon
    else state.map.doubleClickZoom.enable();
  }
}

async function edit(method, path, body) {
  try {
    const r = await fetch(path, {
      method,
      headers: { "Content-Type": "application/json", "X-PFP-Edit": "1" },
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const out = await r.json();
    $("edit-result").textContent = out.ok ? `${method === "DELETE" ? "deleted" : "put"} ${out.key}` : `refused: ${out.field ? out.field + ": " : ""}${out.error}`;
    return !!out.ok;
  } catch (err) {
    $("edit-result").textContent = `map server unreachable (${err})`;
    return false;
  }
}

function num(id) {
  const v = $(id).value.trim();
  return v === "" ? null : Number(v);
}

function threatForm(position) {
  const out = { position, facing_deg: num("new-facing") ?? 0, sigma_range: num("new-sr") ?? 3, sigma_lateral: num("new-sl") ?? 2, skew: num("new-skew") ?? 0 };
  const ttl = num("new-ttl");
  if (ttl !== null && ttl > 0) out.ttl_s = ttl;
  return out;
}

function newThreatId() {
  const given = $("new-id").value.trim();
  if (given) return given;
  let id;
  do id = `map-${++state.dropCount}`;
  while (state.threats.has(id));
  return id;
}

function round2(p) {
  return [Math.round(p[0] * 100) / 100, Math.round(p[1] * 100) / 100];
}

async function onMapClick(e) {
  const p = round2(toMetres(e.latlng));
  const mode = state.mode;
  if (!mode) {
    if (state.selectedUnit) closeUnit();
    if (state.selectedThreat) closeThreat();
    if (state.selectedZone) closeZone();
    return;
  }
  if (mode === "zone-polygon") {
    const last = state.draft[state.draft.length - 1];
    if (!last || last[0] !== p[0] || last[1] !== p[1]) state.draft.push(p); // a double-click's second click adds nothing
    $("zone-finish").hidden = state.draft.length < 3;
    drawDraft(null);
    return;
  }
  if (mode === "zone-centre") {
    state.draft = [p];
    setMode("zone-edge");
    drawDraft(null);
    return;
  }
  if (mode === "zone-edge") {
    const c = state.draft[0];
    const radius = Math.round(Math.hypot(p[0] - c[0], p[1] - c[1]) * 100) / 100;
    setMode(null);
    endDraft();
    await edit("PUT", `/api/zone/${encodeURIComponent(newZoneId())}`, { kind: "keep_out", circle: { centre: c, radius_m: radius } });
    return;
  }
  setMode(null);
  const m = encodeURIComponent;
  if (mode === "drop-threat") await edit("PUT", `/api/threat/${m(newThreatId())}`, threatForm(p));
  else if (mode === "move-threat" && state.threats.has(state.selectedThreat)) {
    const d = state.threats.get(state.selectedThreat).data;
    const body = { ...d.update, position: p }; // the threat as put, whatever its shape, moved
    if (body.ttl_s === null) delete body.ttl_s;
    await edit("PUT", `/api/threat/${m(d.id)}`, body);
  } else if (mode === "set-goal" && state.selectedUnit) await edit("PUT", `/api/goal/${m(state.selectedUnit)}`, { position: p });
}

// -- the stream ----------------------------------------------------------------------------------
// Follow the mission until the operator pans or zooms: keep every unit, goal and threat in view.
function follow() {
  if (state.userMoved) return;
  const pts = [];
  state.units.forEach((u) => {
    if (u.data.position) pts.push(toLatLng(u.data.position));
    if (u.data.goal) pts.push(toLatLng(u.data.goal));
  });
  state.threats.forEach((t) => t.data.zone.forEach((p) => pts.push(toLatLng(p))));
  state.zones.forEach((z) => zonePoints(z.data).forEach((p) => pts.push(toLatLng(p))));
  if (!pts.length) return;
  const b = L.latLngBounds(pts);
  if (state.fitted && state.map.getBounds().contains(b)) return;
  state.map.fitBounds(b.pad(0.15), { maxZoom: state.config.origin ? 19 : 4, animate: false });
  state.fitted = true;
}

function apply(msg) {
  state.offset = msg.now - Date.now() / 1000;
  if (msg.type === "snapshot") {
    if (!state.map) createMap(msg.config);
    [...state.units.keys()].forEach(removeUnit);
    [...state.threats.keys()].forEach((id) => removeThreat(id, false));
    [...state.zones.keys()].forEach((id) => removeZone(id, false));
    $("events").innerHTML = "";
    state.rejected.clear();
  }
  const full = msg.type === "snapshot";
  state.cull = !full && state.units.size > CULL_MIN_UNITS ? state.map.getBounds().pad(0.3) : null;
  Object.values(msg.threats || {}).forEach(upsertThreat);
  (msg.threats_removed || []).forEach((id) => removeThreat(id, false));
  Object.values(msg.zones || {}).forEach(upsertZone);
  (msg.zones_removed || []).forEach((id) => removeZone(id, false));
  Object.values(msg.units || {}).forEach((d) => upsertUnit(d, full));
  (msg.units_removed || []).forEach(removeUnit);
  pfpTeams.apply(msg, full); // teams.js: lead-follow lines, radio circles, cleared corridors
  if (msg.events) {
    addEvents(msg.events);
    const sel = state.selectedUnit;
    if (sel && msg.type === "delta" && msg.events.some((e) => e.kind === "replan" && (e.units.includes(sel) || e.more_units))) schedulePreview();
  }
  if (msg.rejected) {
    Object.values(msg.rejected).forEach((r) => state.rejected.set(r.id, r));
    renderRejected();
  }
  if (msg.status) {
    state.status = Object.assign(state.status || {}, msg.status);
    renderStatus(state.status);
  }
  follow();
}

function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.onopen = () => {
    $("conn").textContent = "live";
    $("conn").className = "conn up";
  };
  ws.onmessage = (ev) => {
    const t0 = performance.now();
    apply(JSON.parse(ev.data));
    const ms = performance.now() - t0;
    const p = state.perf;
    p.frames += 1;
    p.bytes += ev.data.length;
    p.applyMsTotal += ms;
    p.applyMsMax = Math.max(p.applyMsMax, ms);
    // drawn (Leaflet paints on the next animation frame): ask for the next one; a hidden tab has
    // no animation frames, so it asks once a second instead
    let acked = false;
    const ack = () => {
      if (acked || ws.readyState !== WebSocket.OPEN) return;
      acked = true;
      ws.send("ack");
    };
    requestAnimationFrame(ack);
    setTimeout(ack, 1000);
  };
  ws.onclose = () => {
    $("conn").textContent = "reconnecting";
    $("conn").className = "conn down";
    setTimeout(connect, 1000);
  };
}

// ages and TTLs count down between deltas
setInterval(() => {
  state.units.forEach((u) => u.data.stale && u.marker && paintUnit(u));
  state.threats.forEach(paintThreat);
  if (state.selectedUnit) showUnit();
  if (state.selectedThreat) showThreat();
  if (state.selectedZone) showZone();
  if (state.status) renderStatus(state.status);
}, 1000);

$("unit-close").onclick = closeUnit;
$("threat-close").onclick = closeThreat;
$("preview-refresh").onclick = fetchPreview;
$("threat-drop").onclick = () => setMode("drop-threat");
$("threat-move").onclick = () => setMode("move-threat");
$("threat-delete").onclick = () => state.selectedThreat && edit("DELETE", `/api/threat/${encodeURIComponent(state.selectedThreat)}`);
$("goal-set").onclick = () => setMode("set-goal");
$("zone-close").onclick = closeZone;
$("zone-delete").onclick = () => state.selectedZone && edit("DELETE", `/api/zone/${encodeURIComponent(state.selectedZone)}`);
$("zone-draw").onclick = () => startZone("zone-polygon");
$("zone-circle").onclick = () => startZone("zone-centre");
$("zone-finish").onclick = finishPolygon;
$("zone-cancel").onclick = () => {
  setMode(null);
  endDraft();
};
$("goal-cancel").onclick = () => state.selectedUnit && edit("DELETE", `/api/goal/${encodeURIComponent(state.selectedUnit)}`);
connect();
