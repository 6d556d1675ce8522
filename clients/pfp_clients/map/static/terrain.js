// pfp map --terrain: the DEM's hillshade under everything, and the selected threat's viewshed.
// Both are images the server renders on Leaflet's own grid (terrain.py) with their lat/lon corners;
// the layers control toggles them.  map.js calls pfpTerrain.start / .threatSelected / .threatClosed.
"use strict";

const pfpTerrain = {
  shade: null, // {data, layer}: the hillshade as the server sent it, and its overlay
  viewshed: null, // {threat, data, layer}: the selected threat's
  control: null,
  asked: null, // the threat whose viewshed is being fetched

  start(config, map) {
    if (!config.terrain) return;
    map.createPane("terrain").style.zIndex = 250; // over tiles (200), under shapes and markers (400+)
    map.createPane("viewshed").style.zIndex = 260;
    this.control = L.control.layers(null, null, { collapsed: false, position: "topright" }).addTo(map);
    this.control.getContainer().id = "terrain-layers";
    fetch("/api/terrain")
      .then((r) => r.json())
      .then((data) => {
        if (data.error) throw new Error(data.error);
        const layer = L.imageOverlay(data.image, data.bounds, { pane: "terrain", opacity: 0.55, interactive: false, className: "terrain-shade" });
        layer.addTo(map);
        this.shade = { data, layer };
        this.control.addOverlay(layer, `hillshade (${esc(config.terrain.path)})`);
      })
      .catch((err) => console.warn(`terrain: no hillshade (${err})`));
  },

  async threatSelected(id) {
    if (!this.control) return;
    const t = state.threats.get(id);
    const where = t ? JSON.stringify([t.data.position, t.data.observer_height_m]) : "";
    if (this.viewshed && this.viewshed.threat === id && this.viewshed.where === where) return;
    if (this.asked === id && this.askedWhere === where) return;
    this.threatClosed();
    this.asked = id;
    this.askedWhere = where;
    $("threat-viewshed").textContent = "viewshed: computing…";
    let body;
    try {
      body = await (await fetch(`/api/viewshed/${encodeURIComponent(id)}`)).json();
    } catch (err) {
      body = { error: `map server unreachable (${err})` };
    }
    if (this.asked !== id) return; // another threat was clicked meanwhile
    this.asked = null;
    if (body.error) {
      $("threat-viewshed").textContent = `viewshed: ${body.error}`;
      return;
    }
    const layer = L.imageOverlay(body.image, body.bounds, { pane: "viewshed", opacity: 1, interactive: false, className: "threat-viewshed" });
    layer.addTo(state.map);
    this.viewshed = { threat: id, where, data: body, layer };
    this.control.addOverlay(layer, `viewshed of ${esc(id)}`);
    const share = body.cells ? (100 * body.seen_cells) / body.cells : 0;
    $("threat-viewshed").textContent =
      `viewshed: sees ${share.toFixed(0)} % of the ground within ${(body.radius_m / 1000).toFixed(1)} km ` +
      `(eye ${body.observer_height_m} m, target ${body.target_height_m} m)`;
  },

  threatClosed() {
    this.asked = null;
    if (this.viewshed) {
      state.map.removeLayer(this.viewshed.layer);
      this.control.removeLayer(this.viewshed.layer);
      this.viewshed = null;
    }
    const el = $("threat-viewshed");
    if (el) el.textContent = "";
  },
};
window.pfpTerrain = pfpTerrain;
