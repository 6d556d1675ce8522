// pfp map: teams. A line from each lead to each of its followers, each controller's radio circle
// (radio_range_m round it), and the cleared corridor: the lead's track, corridor_m wide at any zoom.
// map.js calls pfpTeams.apply(msg, full) after it has placed the units of a snapshot or delta.
"use strict";

const TEAM_COLOUR = "#7b2cbf";

const pfpTeams = {
  teams: new Map(), // id -> the team's view, as the server sent it
  drawn: new Map(), // id -> {links, circle, corridor}: its layers
  layer: null,

  apply(msg, full) {
    if (!this.layer) {
      this.layer = L.layerGroup().addTo(state.map);
      state.map.on("zoomend", () => this.teams.forEach((_t, id) => this.draw(id)));
    }
    if (full) [...this.teams.keys()].forEach((id) => this.remove(id));
    Object.values(msg.teams || {}).forEach((t) => this.teams.set(t.id, t));
    (msg.teams_removed || []).forEach((id) => this.remove(id));
    // members move with every delta: redraw the teams whose members did, and those just put
    const moved = new Set(Object.keys(msg.units || {}));
    this.teams.forEach((t, id) => {
      const members = [t.lead, ...t.follow, t.controller, ...t.robots, ...t.members];
      if (full || (msg.teams && msg.teams[id]) || members.some((u) => moved.has(u))) this.draw(id);
    });
  },

  at(unit) {
    const u = unit && state.units.get(unit);
    return u && u.data.position ? toLatLng(u.data.position) : null;
  },

  metresPerPixel() {
    const m = state.map;
    const c = m.getSize().divideBy(2);
    const a = toMetres(m.containerPointToLatLng(c));
    const b = toMetres(m.containerPointToLatLng(c.add([100, 0])));
    return Math.hypot(b[0] - a[0], b[1] - a[1]) / 100;
  },

  draw(id) {
    const t = this.teams.get(id);
    const d = this.drawn.get(id) || { links: [], circle: null, corridor: null };
    this.drawn.set(id, d);
    d.links.forEach((l) => this.layer.removeLayer(l));
    d.links = [];
    const lead = this.at(t.lead);
    t.follow.forEach((f) => {
      const at = this.at(f);
      if (lead && at) {
        const line = L.polyline([lead, at], { color: TEAM_COLOUR, weight: 2, dashArray: "6 4", interactive: false });
        d.links.push(line.bindTooltip(`team ${esc(id)}: ${esc(f)} follows ${esc(t.lead)}`).addTo(this.layer));
      }
    });
    const ctl = this.at(t.controller);
    if (d.circle && !ctl) {
      this.layer.removeLayer(d.circle);
      d.circle = null;
    } else if (ctl && t.robots.length) {
      if (!d.circle) {
        d.circle = L.circle(ctl, { radius: t.radio_range_m, color: TEAM_COLOUR, weight: 1, fill: false, dashArray: "2 4", interactive: false });
        d.circle.addTo(this.layer).bindTooltip(`team ${esc(id)}: ${esc(t.controller)}'s radio, ${t.radio_range_m} m`);
      } else d.circle.setLatLng(ctl);
    }
    const track = (t.track || []).map(toLatLng);
    const weight = Math.max(2, t.corridor_m / this.metresPerPixel());
    if (!d.corridor) {
      d.corridor = L.polyline(track, { color: TEAM_COLOUR, weight, opacity: 0.18, lineCap: "round", lineJoin: "round", interactive: false });
      d.corridor.addTo(this.layer);
    } else d.corridor.setLatLngs(track).setStyle({ weight });
    d.corridorWeightPx = weight;
  },

  remove(id) {
    const d = this.drawn.get(id);
    if (d) {
      d.links.forEach((l) => this.layer.removeLayer(l));
      if (d.circle) this.layer.removeLayer(d.circle);
      if (d.corridor) this.layer.removeLayer(d.corridor);
    }
    this.drawn.delete(id);
    this.teams.delete(id);
  },
};
window.pfpTeams = pfpTeams;
