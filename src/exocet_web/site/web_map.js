// Exocet web map: the dive's mosaic as it grows, with the vehicle, its track, the USBL fixes and the tile footprints.
// Served live by web_map_node (the state at /state.json, then the changes as Server-Sent Events at /events), or
// opened from the site folder after the dive (a static web server, or file:// where the state comes from state.js).
// Nothing is loaded from outside the site folder.
(function () {
  'use strict';

  const LIVE = location.protocol === 'http:' || location.protocol === 'https:';
  const BLANK = 'data:image/gif;base64,R0lGODlhAQABAIAAAAAAAP///yH5BAEAAAAALAAAAAABAAEAAAIBRAA7';

  // What a test reads (and the page's title repeats): tile loads and errors, events, track length.
  const stats = {
    tileLoads: 0, tileErrors: 0, failedTiles: [], events: 0, resets: 0, webTileEvents: 0, tileEvents: 0,
    trackPoints: 0, usblFixes: 0, footprints: 0, connected: false, lastEventId: null, loadedRevs: {},
    pageLoadedAt: Date.now(), lastTile: null, cutEventIds: {}, cutVersions: {}, cutDoneIds: {},
  };

  const map = L.map('map', { zoomControl: true, maxZoom: 28, worldCopyJump: false });
  map.attributionControl.setPrefix('Leaflet');
  map.attributionControl.addAttribution('Exocet');
  L.control.scale({ imperial: false, maxWidth: 220 }).addTo(map);
  map.setView([0, 0], 2);

  // ---- Web tiles of the mosaic ------------------------------------------------------------------------------------
  let zoom = { min: -1, max: -1 };
  let finest = new Set();           // "x,y" of the web tiles at zoom.max
  let levels = new Map();           // z -> Set of "x,y": the tiles at coarser levels, from the finest
  // "x,y" of finest tiles announced before their coarser levels (a cut announces its finest level first): no parent
  // of theirs is asked for until the cut's "coarser" event.
  let awaitingParents = new Set();
  let baseRev = 0;                  // event id of the snapshot
  const rev = new Map();            // "z/x/y" -> event id of its last change
  // The node's run ("<run>-<n>" ids) in the tile URLs too: a restarted node counts from 0 again, and the browser
  // would show an image it holds for an URL of the killed run.
  let run = '';

  function levelSet(z) {
    if (z === zoom.max) return finest;
    if (!levels.has(z)) {
      const s = new Set(), shift = zoom.max - z;
      for (const k of finest) {
        if (awaitingParents.has(k)) continue;
        const [x, y] = k.split(',');
        s.add((x >> shift) + ',' + (y >> shift));
      }
      levels.set(z, s);
    }
    return levels.get(z);
  }
  function tileExists(z, x, y) {
    if (zoom.max < 0 || z > zoom.max || z < zoom.min) return false;
    return levelSet(z).has(x + ',' + y);
  }
  function addFinest(x, y, parentsBuilt) {
    finest.add(x + ',' + y);
    if (!parentsBuilt) { awaitingParents.add(x + ',' + y); return; }
    awaitingParents.delete(x + ',' + y);
    for (const [z, s] of levels) s.add((x >> (zoom.max - z)) + ',' + (y >> (zoom.max - z)));
  }
  function parentsBuilt() {
    const waiting = Array.from(awaitingParents);
    awaitingParents = new Set();
    for (const k of waiting) {
      const [x, y] = k.split(',').map(Number);
      addFinest(x, y, true);
    }
  }

  const MosaicLayer = L.TileLayer.extend({
    getTileUrl: function (coords) {
      if (!tileExists(coords.z, coords.x, coords.y)) return BLANK;
      const key = coords.z + '/' + coords.x + '/' + coords.y;
      if (!LIVE) return 'tiles/' + key + '.png';
      return 'tiles/' + key + '.png?r=' + (rev.get(key) || baseRev) + (run ? '&run=' + encodeURIComponent(run) : '');
    },
  });
  const mosaic = new MosaicLayer('', { tileSize: 256, maxZoom: 28, minZoom: 0, keepBuffer: 1, updateWhenZooming: false });
  mosaic.on('tileload', function (e) {
    if (e.tile.src.startsWith('data:')) return;
    stats.tileLoads += 1;
    const m = /[?&]r=(\d+)/.exec(e.tile.src);
    if (m) stats.loadedRevs[e.coords.z + '/' + e.coords.x + '/' + e.coords.y] = Number(m[1]);
    showTitle();
  });
  mosaic.on('tileerror', function (e) {
    stats.tileErrors += 1;
    if (stats.failedTiles.length < 20) stats.failedTiles.push(e.tile.src);
    showTitle();
  });
  mosaic.addTo(map);

  function setZoomRange(z) {
    if (z.max !== zoom.max) { finest = new Set(); levels = new Map(); awaitingParents = new Set(); }
    if (z.min !== zoom.min) levels = new Map();
    zoom = { min: z.min, max: z.max };
    if (zoom.max < 0) return;
    mosaic.options.minNativeZoom = zoom.min;
    mosaic.options.maxNativeZoom = zoom.max;
    // Far below the coarsest level a viewport would hold thousands of tile positions: the track is enough there.
    mosaic.options.minZoom = Math.max(0, zoom.min - 1);
    map.setMaxZoom(zoom.max + 3);
  }
  function setMosaicBounds(bounds) {
    mosaic.options.bounds = bounds ? L.latLngBounds([bounds[0], bounds[1]], [bounds[2], bounds[3]]).pad(0.05) : null;
  }
  // Re-fetches the tiles on screen whose key changed (a re-cut web tile, or one that now exists).
  function refreshTiles(keys) {
    for (const id in mosaic._tiles) {
      const t = mosaic._tiles[id];
      const key = t.coords.z + '/' + t.coords.x + '/' + t.coords.y;
      if (keys.has(key)) t.el.src = mosaic.getTileUrl(t.coords);
    }
  }

  // ---- Overlays ---------------------------------------------------------------------------------------------------
  const track = L.polyline([], { color: '#ffd21f', weight: 2, opacity: 0.9, interactive: false });
  const vehicleIcon = L.divIcon({
    className: 'exocet-vehicle', iconSize: [28, 28], iconAnchor: [14, 14],
    html: '<svg viewBox="-14 -14 28 28" width="28" height="28"><g class="arrow">' +
          '<path d="M0,-12 L7,9 L0,4 L-7,9 Z" fill="#ff3b30" stroke="#fff" stroke-width="1.5"/></g></svg>',
  });
  const vehicle = L.marker([0, 0], { icon: vehicleIcon, interactive: false, keyboard: false });
  const vehicleLayer = L.layerGroup([]);
  const usbl = L.layerGroup([]);
  const footprints = L.layerGroup([]);
  const footprintByKey = new Map();
  track.addTo(map);
  vehicleLayer.addTo(map);
  usbl.addTo(map);
  footprints.addTo(map);
  L.control.layers(null, {
    'Mosaic': mosaic, 'Track': track, 'Vehicle': vehicleLayer, 'USBL fixes': usbl, 'Tile footprints': footprints,
  }, { collapsed: false, position: 'topright' }).addTo(map);

  let datum = null;  // {utm_zone, northern, epsg}
  let haveVehicle = false;
  let lastVehicle = null;

  function formatTime(t) {
    if (typeof t !== 'number' || !isFinite(t)) return '-';
    return new Date(t * 1000).toISOString().replace('T', ' ').replace('Z', ' UTC');
  }
  function escapeHtml(s) {
    return String(s).replace(/[&<>"']/g, c => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' })[c]);
  }
  function tilePopup(t) {
    const m = t.metadata || {};
    const rows = [
      ['tile', t.index + (t.version > 1 ? ' (version ' + t.version + ')' : '')],
      ['file', t.file],
      ['time', formatTime(m.start_time_s) + ' to ' + formatTime(m.end_time_s)],
      ['gsd', (t.gsd_m * 1000).toFixed(2) + ' mm'],
      ['frames', (m.first_frame !== undefined ? m.first_frame + ' to ' + m.last_frame : '-') +
                 (m.frames_composed !== undefined ? ' (' + m.frames_composed + ' composed)' : '')],
      ['position sigma', m.position_sigma_m !== undefined ? Number(m.position_sigma_m).toFixed(3) + ' m' : '-'],
      ['altitude', m.mean_altitude_m !== undefined ? Number(m.mean_altitude_m).toFixed(2) + ' m' : '-'],
      ['closed by', m.close_reason || '-'],
      ['size', t.width_px + ' x ' + t.height_px + ' px, EPSG:' + t.epsg],
    ];
    return '<table class="exocet-meta">' +
           rows.map(r => '<tr><th>' + escapeHtml(r[0]) + '</th><td>' + escapeHtml(r[1]) + '</td></tr>').join('') +
           '</table>';
  }
  function setTile(t) {
    const old = footprintByKey.get(t.key);
    if (old) footprints.removeLayer(old);
    const polygon = L.polygon(t.corners, { color: '#3fa9f5', weight: 1, fill: false, dashArray: '4 3' });
    polygon.bindPopup(tilePopup(t));
    // Clicks anywhere inside the footprint, not only on its outline.
    polygon.setStyle({ fill: true, fillOpacity: 0 });
    footprints.addLayer(polygon);
    footprintByKey.set(t.key, polygon);
    stats.footprints = footprintByKey.size;
  }
  function addUsbl(f) {
    const marker = L.circleMarker([f[0], f[1]], { radius: 3, color: '#ff5edb', weight: 1, fillOpacity: 0.8 });
    marker.bindPopup('USBL fix<br>' + escapeHtml(formatTime(f[2])) +
                     (typeof f[3] === 'number' ? '<br>sigma ' + f[3].toFixed(2) + ' m' : ''));
    usbl.addLayer(marker);
    stats.usblFixes += 1;
  }
  function setVehicle(v) {
    if (!v) return;
    lastVehicle = v;
    vehicle.setLatLng([v.lat, v.lon]);
    if (!haveVehicle) { vehicleLayer.addLayer(vehicle); haveVehicle = true; }
    const heading = typeof v.heading_deg === 'number' ? v.heading_deg : v.course_deg;
    const el = vehicle.getElement();
    if (el) {
      const arrow = el.querySelector('.arrow');
      if (arrow) {
        arrow.setAttribute('transform', 'rotate(' + (typeof heading === 'number' ? heading : 0) + ')');
        arrow.style.opacity = typeof heading === 'number' ? 1 : 0.5;
      }
    }
    if (follow) map.panTo([v.lat, v.lon], { animate: false });
  }

  // ---- Controls: follow, cursor position, distance ----------------------------------------------------------------
  let follow = true;
  const FollowControl = L.Control.extend({
    options: { position: 'topleft' },
    onAdd: function () {
      const b = L.DomUtil.create('button', 'exocet-button exocet-follow');
      b.type = 'button';
      b.title = 'Keep the vehicle in view';
      b.textContent = 'Follow vehicle';
      L.DomEvent.disableClickPropagation(b);
      L.DomEvent.on(b, 'click', () => {
        setFollow(true);
        if (lastVehicle) map.panTo([lastVehicle.lat, lastVehicle.lon]);
      });
      this.button = b;
      return b;
    },
  });
  const followControl = new FollowControl().addTo(map);
  function setFollow(on) {
    follow = on;
    followControl.button.classList.toggle('active', on);
  }
  setFollow(true);
  map.on('dragstart', () => setFollow(false));

  const CursorControl = L.Control.extend({
    options: { position: 'bottomleft' },
    onAdd: function () {
      this.div = L.DomUtil.create('div', 'exocet-cursor');
      this.div.textContent = 'move the pointer over the map';
      return this.div;
    },
  });
  const cursor = new CursorControl().addTo(map);
  function utmText(lat, lon) {
    const zone = datum && datum.utm_zone > 0 ? datum.utm_zone : ExocetGeo.utmZone(lon);
    const northern = datum && datum.utm_zone > 0 ? datum.northern : lat >= 0;
    const u = ExocetGeo.toUtm(lat, lon, zone, northern);
    return 'UTM ' + zone + (northern ? 'N' : 'S') + ' E ' + u.easting.toFixed(2) + ' m, N ' + u.northing.toFixed(2) + ' m';
  }
  map.on('mousemove', function (e) {
    const lat = e.latlng.lat, lon = e.latlng.lng;
    cursor.div.textContent = lat.toFixed(7) + ', ' + lon.toFixed(7) + '  (' +
        ExocetGeo.degreesMinutes(lat, 'N', 'S') + ' ' + ExocetGeo.degreesMinutes(lon, 'E', 'W') + ')  ' +
        utmText(lat, lon);
  });

  let measuring = false, measurePoints = [];
  const measureLayer = L.layerGroup([]).addTo(map);
  const MeasureControl = L.Control.extend({
    options: { position: 'topleft' },
    onAdd: function () {
      const b = L.DomUtil.create('button', 'exocet-button');
      b.type = 'button';
      b.title = 'Measure a distance: click two points on the map';
      b.textContent = 'Measure';
      L.DomEvent.disableClickPropagation(b);
      L.DomEvent.on(b, 'click', () => {
        measuring = !measuring;
        b.classList.toggle('active', measuring);
        measurePoints = [];
        measureLayer.clearLayers();
        map.getContainer().style.cursor = measuring ? 'crosshair' : '';
      });
      return b;
    },
  });
  new MeasureControl().addTo(map);
  map.on('click', function (e) {
    if (!measuring) return;
    if (measurePoints.length === 2) { measurePoints = []; measureLayer.clearLayers(); }
    measurePoints.push(e.latlng);
    measureLayer.addLayer(L.circleMarker(e.latlng, { radius: 4, color: '#fff', weight: 2 }));
    if (measurePoints.length === 2) {
      const [a, b] = measurePoints;
      const d = ExocetGeo.distance(a.lat, a.lng, b.lat, b.lng);
      const line = L.polyline([a, b], { color: '#fff', weight: 2, dashArray: '6 4' });
      line.bindTooltip(d < 10 ? d.toFixed(3) + ' m' : d.toFixed(2) + ' m', { permanent: true, className: 'exocet-distance' });
      measureLayer.addLayer(line);
      window.EXOCET_LAST_DISTANCE_M = d;
    }
  });

  const StatusControl = L.Control.extend({
    options: { position: 'bottomright' },
    onAdd: function () {
      this.div = L.DomUtil.create('div', 'exocet-status');
      return this.div;
    },
  });
  const status = new StatusControl().addTo(map);
  let diveName = '';
  function showTitle() {
    document.title = 'Exocet web map' + (diveName ? ' ' + diveName : '') + ' | tiles loaded ' + stats.tileLoads +
                     ' | tile errors ' + stats.tileErrors + ' | track ' + stats.trackPoints;
    status.div.textContent = (LIVE ? (stats.connected ? 'live' : 'connecting...') : 'recorded dive') + ' | ' +
                             stats.footprints + ' tiles | track ' + stats.trackPoints + ' points';
  }

  // ---- State and events -------------------------------------------------------------------------------------------
  function eventNumber(id) {
    const m = /-(\d+)$/.exec(id || '');
    return m ? Number(m[1]) : 0;
  }
  function runOf(id) {
    const m = /^(.+)-\d+$/.exec(id || '');
    return m ? m[1] : '';
  }
  let fitted = false;
  function applyState(s) {
    diveName = s.dive_name || '';
    datum = s.datum;
    baseRev = eventNumber(s.event_id);
    run = runOf(s.event_id);
    rev.clear();
    setZoomRange(s.zoom || { min: -1, max: -1 });
    finest = new Set();
    levels = new Map();
    awaitingParents = new Set();
    if (s.web_tiles && s.web_tiles.z === zoom.max) {
      for (const xy of s.web_tiles.xy) finest.add(xy[0] + ',' + xy[1]);
      for (const xy of s.web_tiles.awaiting_parents || []) awaitingParents.add(xy[0] + ',' + xy[1]);
    }
    setMosaicBounds(s.bounds);
    footprints.clearLayers();
    footprintByKey.clear();
    for (const t of s.tiles || []) setTile(t);
    track.setLatLngs((s.track || []).map(p => [p[0], p[1]]));
    stats.trackPoints = (s.track || []).length;
    usbl.clearLayers();
    stats.usblFixes = 0;
    for (const f of s.usbl || []) addUsbl(f);
    if (!fitted && s.bounds) {
      map.fitBounds([[s.bounds[0], s.bounds[1]], [s.bounds[2], s.bounds[3]]], { maxZoom: zoom.max });
      fitted = true;
      setFollow(LIVE);
    } else if (!fitted && s.vehicle) {
      map.setView([s.vehicle.lat, s.vehicle.lon], Math.max(zoom.max, 20));
      fitted = true;
    }
    setVehicle(s.vehicle);
    mosaic.redraw();
    showTitle();
  }

  function onTile(t) {
    stats.tileEvents += 1;
    stats.lastTile = t.key;
    setTile(t);
    if (!fitted) {
      map.fitBounds([[t.bounds[0], t.bounds[1]], [t.bounds[2], t.bounds[3]]]);
      fitted = true;
    }
  }
  function onWebTiles(d, id) {
    stats.webTileEvents += 1;
    // A cut comes as two events, the finest level first: the first one of each version is the cut's.
    if (d.levels !== 'coarser' || stats.cutVersions[d.key] !== d.version) stats.cutEventIds[d.key] = id;
    stats.cutVersions[d.key] = d.version;
    if (d.levels !== 'finest') stats.cutDoneIds[d.key] = id;  // every level of this version is cut
    const zoomChanged = d.zoom.min !== zoom.min || d.zoom.max !== zoom.max;
    if (zoomChanged) setZoomRange(d.zoom);
    const changed = new Set();
    if (d.levels !== 'finest') parentsBuilt();
    for (const [z, x, y] of d.written) {
      const key = z + '/' + x + '/' + y;
      rev.set(key, id);
      changed.add(key);
      if (z === zoom.max) addFinest(x, y, d.levels !== 'finest');
    }
    let removedAny = false;
    for (const [z, x, y] of d.removed) {
      const key = z + '/' + x + '/' + y;
      rev.set(key, id);
      changed.add(key);
      if (z === zoom.max) { finest.delete(x + ',' + y); removedAny = true; }
    }
    if (removedAny) levels = new Map();
    const bounds = [];
    for (const polygon of footprintByKey.values()) bounds.push(polygon.getBounds());
    if (bounds.length) {
      const b = bounds.reduce((a, c) => a.extend(c), L.latLngBounds(bounds[0].getSouthWest(), bounds[0].getNorthEast()));
      setMosaicBounds([b.getSouth(), b.getWest(), b.getNorth(), b.getEast()]);
    }
    if (zoomChanged) mosaic.redraw(); else refreshTiles(changed);
  }
  function onTrack(d) {
    for (const p of d.points) track.addLatLng([p[0], p[1]]);
    stats.trackPoints += d.points.length;
    if (d.vehicle) setVehicle(d.vehicle);
    if (!fitted && d.vehicle) {
      map.setView([d.vehicle.lat, d.vehicle.lon], zoom.max > 0 ? zoom.max : 22);
      fitted = true;
    }
    showTitle();
  }

  function listen(state) {
    const source = new EventSource('events?after=' + encodeURIComponent(state.event_id));
    const handle = (name, fn) => source.addEventListener(name, function (e) {
      stats.events += 1;
      stats.lastEventId = e.lastEventId;
      try {
        fn(JSON.parse(e.data), eventNumber(e.lastEventId), e.lastEventId);
      } catch (err) {
        console.error(name, err);
      }
    });
    handle('tile', onTile);
    handle('webtiles', onWebTiles);
    handle('track', onTrack);
    handle('usbl', d => { for (const f of d.fixes) addUsbl(f); });
    handle('datum', d => { datum = d; });
    handle('reset', (d, n, id) => {
      stats.resets += 1;
      // Until the state comes, a re-cut web tile is fetched under the new run's numbers.
      run = runOf(id);
      baseRev = n;
      rev.clear();
      loadState(false);
    });
    source.onopen = () => { stats.connected = true; showTitle(); };
    source.onerror = () => {
      stats.connected = false;
      showTitle();
      // The browser reconnects by itself when the node is down (a restart), but gives up on an HTTP error (503 when
      // the node is busy): then a fresh state and a new stream.
      if (source.readyState === EventSource.CLOSED) setTimeout(() => loadState(true), 2000);
    };
  }

  function loadState(thenListen) {
    return fetch('state.json', { cache: 'no-store' })
      .then(r => { if (!r.ok) throw new Error('state.json: HTTP ' + r.status); return r.json(); })
      .then(s => { applyState(s); if (thenListen) listen(s); })
      .catch(err => {
        console.error(err);
        if (window.EXOCET_STATE) applyState(window.EXOCET_STATE);
        if (thenListen) setTimeout(() => loadState(true), 2000);
      });
  }

  // For tests and the browser's console.
  window.EXOCET = { map: map, mosaic: mosaic, stats: stats, tileExists: tileExists, setFollow: setFollow,
                    following: () => follow, zoom: () => zoom, mosaicLoading: () => mosaic.isLoading(),
                    footprintBounds: key => footprintByKey.has(key) ? footprintByKey.get(key).getBounds() : null };
  if (LIVE) {
    if (window.EXOCET_STATE) applyState(window.EXOCET_STATE);  // at once, then the live state
    loadState(true);
  } else if (window.EXOCET_STATE) {
    applyState(window.EXOCET_STATE);
  }
  showTitle();
})();
