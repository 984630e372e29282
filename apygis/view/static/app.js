// apygis view: draws the map (and a session as it compiles) on a canvas.
//
// The server pushes JSON messages over a WebSocket (apygis/view/hub.py):
// "state" (everything), "delta" (one change, seq one more than the last) and
// "status" (the status line and the floating mark). The page only views:
// it sends nothing. Records are lists in the field order of
// apygis/model/records.py; coordinates are metres of the map's CRS.
//
// Drawing follows the plot: pens by layer, kind and code; symbols are the
// painted cells of their 15x15 bitmaps, texts and spot heights are sized in
// paper millimetres; everything at the display scale factor (1x: one
// millimetre of the map sheet is one millimetre on the screen).
//
// window.apygisView is a read-only hook for tests and curious users.
"use strict";

(function () {
  const MM_PX = 96 / 25.4; // CSS pixels per millimetre
  const CAP_HEIGHT = 0.718; // cap height of a sans-serif font as a fraction of its size
  const TABLES = ["symbols", "line_points", "texts"];
  const WORDS = { symbols: "symbol", line_points: "line point", texts: "text" };
  const HIT_PX = 8;

  const S = {
    seq: -1,
    kind: "",
    meta: {},
    pens: {},
    layerPens: {},
    style: { symbol_size_mm: 3, text_height_mm: 2.5, height_decimals: 1 },
    symbols: {},
    layers: new Map(), // ext -> {symbols: Map, line_points: Map, texts: Map}
    entries: [],
    entriesBefore: 0,
    messages: [],
    overlays: [],
    status: {},
    display: { scale: 1, crosshair: 1 },
    ended: false,
    hidden: new Set(),
  };
  const V = { cx: 0, cy: 0, factor: 1, placed: false, follow: true };
  const log = { states: 0, deltas: 0, statuses: 0, received: [] };
  let drawn = {};
  let selected = null;
  let connected = false;
  let ws = null;
  let frame = 0;
  let symCache = new Map();

  const $ = (id) => document.getElementById(id);
  const canvas = $("map");
  const ctx = canvas.getContext("2d");

  // ------------------------------------------------------------------ state

  function tablesOf(ext) {
    let t = S.layers.get(ext);
    if (!t) {
      t = { symbols: new Map(), line_points: new Map(), texts: new Map() };
      S.layers.set(ext, t);
    }
    return t;
  }

  function loadState(m) {
    S.seq = m.seq;
    S.kind = m.kind;
    S.meta = m.map || {};
    S.pens = m.pens || {};
    S.layerPens = m.layer_pens || {};
    S.style = m.style || S.style;
    S.symbols = m.symbols || {};
    S.layers = new Map();
    for (const ext of Object.keys(m.layers || {}).sort()) {
      const t = tablesOf(ext);
      for (const name of TABLES) {
        for (const r of m.layers[ext][name] || []) t[name].set(r[0], r);
      }
    }
    S.entries = m.entries || [];
    S.entriesBefore = m.entries_before || 0;
    S.messages = m.messages || [];
    S.overlays = m.overlays || [];
    S.status = m.status || {};
    const oldScale = S.display.scale;
    S.display = m.display || S.display;
    S.ended = !!m.ended;
    symCache = new Map();
    if (!V.placed) {
      if (S.kind === "session" && S.status.mark) placeAt(S.status.mark[0], S.status.mark[1], S.display.scale);
      else fit();
      V.placed = true;
    } else if (S.display.scale !== oldScale) {
      applyDisplayFactor();
    }
    renderPanels(true);
  }

  function applyDelta(m) {
    if (m.seq <= S.seq) return; // already in a state received later
    S.seq = m.seq;
    if (m.pens) S.pens = m.pens;
    if (m.layer_pens) Object.assign(S.layerPens, m.layer_pens);
    for (const [ext, tables] of Object.entries(m.upsert || {})) {
      const t = tablesOf(ext);
      for (const [name, rows] of Object.entries(tables)) for (const r of rows) t[name].set(r[0], r);
    }
    for (const [ext, tables] of Object.entries(m.remove || {})) {
      const t = tablesOf(ext);
      for (const [name, nums] of Object.entries(tables)) for (const n of nums) t[name].delete(n);
    }
    for (const ext of Object.keys(m.layer_pens || {})) tablesOf(ext);
    if (m.entries) {
      const last = S.entries.length ? S.entries[S.entries.length - 1][0] : S.entriesBefore;
      for (const e of m.entries) if (e[0] > last) S.entries.push(e);
    }
    if (m.messages) S.messages = S.messages.concat(m.messages).slice(-200);
    if (m.overlays) {
      S.overlays = S.overlays.concat(m.overlays);
      const res = S.overlays.filter((o) => o.kind === "area" || o.kind === "dhi");
      if (res.length > 50) {
        const drop = new Set(res.slice(0, res.length - 50));
        S.overlays = S.overlays.filter((o) => !drop.has(o));
      }
    }
    if (m.display) setDisplay(m.display);
    if (m.ended) S.ended = true;
    if (selected && !recordOf(selected)) selected = null;
    renderPanels(!!(m.layer_pens || m.upsert || m.remove));
  }

  function applyStatus(m) {
    S.status = m;
    if (m.display) setDisplay(m.display);
    if (V.follow && m.mark) keepInView(m.mark[0], m.mark[1]);
    renderStatus();
  }

  function setDisplay(d) {
    const changed = d.scale !== S.display.scale;
    S.display = d;
    if (changed) applyDisplayFactor();
  }

  function applyDisplayFactor() {
    const mk = S.status.mark;
    if (mk) placeAt(mk[0], mk[1], S.display.scale);
    else V.factor = S.display.scale;
    symCache = new Map();
  }

  function recordOf(sel) {
    const t = S.layers.get(sel.ext);
    return t ? t[sel.table].get(sel.num) : undefined;
  }

  // ------------------------------------------------------------------ view

  function pxPerM() {
    const scale = S.meta.scale || 1000;
    return (V.factor * 1000 * MM_PX) / scale;
  }
  function toScreen(x, y) {
    const k = pxPerM();
    return [canvas.clientWidth / 2 + (x - V.cx) * k, canvas.clientHeight / 2 - (y - V.cy) * k];
  }
  function toGround(px, py) {
    const k = pxPerM();
    return [V.cx + (px - canvas.clientWidth / 2) / k, V.cy - (py - canvas.clientHeight / 2) / k];
  }
  function placeAt(x, y, factor) {
    V.cx = x;
    V.cy = y;
    if (factor) V.factor = factor;
    symCache = new Map();
    redraw();
  }
  function zoomAbout(px, py, f) {
    const [gx, gy] = toGround(px, py);
    V.factor = Math.min(1000, Math.max(0.001, V.factor * f));
    const k = pxPerM();
    V.cx = gx - (px - canvas.clientWidth / 2) / k;
    V.cy = gy + (py - canvas.clientHeight / 2) / k;
    symCache = new Map();
    redraw();
  }
  function extent() {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (const [ext, t] of S.layers) {
      if (S.hidden.has(ext)) continue;
      for (const name of TABLES)
        for (const r of t[name].values()) {
          if (r[1] < x0) x0 = r[1];
          if (r[1] > x1) x1 = r[1];
          if (r[2] < y0) y0 = r[2];
          if (r[2] > y1) y1 = r[2];
        }
    }
    for (const o of S.overlays)
      if (o.kind === "control") {
        x0 = Math.min(x0, o.x); x1 = Math.max(x1, o.x);
        y0 = Math.min(y0, o.y); y1 = Math.max(y1, o.y);
      }
    return x0 <= x1 ? [x0, y0, x1, y1] : null;
  }
  function fit() {
    const e = extent();
    if (!e) return placeAt(0, 0, 1);
    const w = Math.max(canvas.clientWidth, 100) * 0.85, h = Math.max(canvas.clientHeight, 100) * 0.85;
    const scale = S.meta.scale || 1000;
    const dx = Math.max(e[2] - e[0], 1e-3), dy = Math.max(e[3] - e[1], 1e-3);
    const k = Math.min(w / dx, h / dy); // px per m
    placeAt((e[0] + e[2]) / 2, (e[1] + e[3]) / 2, Math.min(1000, (k * scale) / (1000 * MM_PX)));
  }
  function keepInView(x, y) {
    const [sx, sy] = toScreen(x, y);
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (sx < w * 0.1 || sx > w * 0.9 || sy < h * 0.1 || sy > h * 0.9) placeAt(x, y);
  }

  // ------------------------------------------------------------------ drawing

  function redraw() {
    if (!frame) frame = requestAnimationFrame(draw);
  }

  function pen(n) {
    return S.pens[String(n)] || { colour: "#000000", width_mm: 0.25 };
  }
  function penOf(ext, kind, code) {
    const lp = S.layerPens[ext];
    if (!lp) return 1;
    return kind === "texts" ? lp.texts : lp[kind][code] ?? 1;
  }

  function symbolImage(code, colour, cell) {
    const key = code + "|" + colour + "|" + cell.toFixed(3);
    let img = symCache.get(key);
    if (img) return img;
    const dpr = window.devicePixelRatio || 1;
    const n = 15, size = Math.max(1, Math.ceil(n * cell * dpr));
    img = document.createElement("canvas");
    img.width = img.height = size;
    const c = img.getContext("2d");
    c.fillStyle = colour;
    const s = symbolRows(code);
    const cp = (cell * dpr);
    for (let r = 0; r < n; r++) {
      const bits = s[r];
      for (let col = 0; col < n; col++) {
        if (bits & (1 << (n - 1 - col))) c.fillRect(col * cp, r * cp, Math.max(cp, 0.6), Math.max(cp, 0.6));
      }
    }
    symCache.set(key, img);
    return img;
  }
  function symbolRows(code) {
    const s = S.symbols[String(code)];
    if (s) return s.rows;
    // a code without a bitmap: an open square of 5x5 cells, as the plot draws it
    const rows = new Array(15).fill(0);
    const edge = 0b000001111100000, side = 0b000001000100000;
    rows[5] = rows[9] = edge;
    rows[6] = rows[7] = rows[8] = side;
    return rows;
  }

  function draw() {
    frame = 0;
    const dpr = window.devicePixelRatio || 1;
    const W = canvas.clientWidth, H = canvas.clientHeight;
    if (canvas.width !== Math.round(W * dpr) || canvas.height !== Math.round(H * dpr)) {
      canvas.width = Math.round(W * dpr);
      canvas.height = Math.round(H * dpr);
    }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.clearRect(0, 0, W, H);
    const k = pxPerM();
    const mmPx = V.factor * MM_PX; // screen px per paper mm
    const ox = W / 2 - V.cx * k, oy = H / 2 + V.cy * k;
    const X = (x) => ox + x * k, Y = (y) => oy - y * k;
    const st = S.style;
    const stats = { segments: 0, points: 0, symbols: 0, spot_heights: 0, texts: 0, overlays: 0, mark: false, layers: [] };
    const margin = 50;
    const vis = (sx, sy) => sx > -margin && sx < W + margin && sy > -margin && sy < H + margin;
    const exts = [...S.layers.keys()].sort();
    for (const ext of exts) {
      if (S.hidden.has(ext)) continue;
      stats.layers.push(ext);
      const t = S.layers.get(ext);
      // -- lines: a segment from each point to its forward neighbour, and from a backward
      //    neighbour that does not lead here (a branch starting at a junction)
      const paths = new Map();
      const lp = t.line_points;
      for (const p of lp.values()) {
        const pn = penOf(ext, "lines", p[4]);
        let path = paths.get(pn);
        if (!path) { path = new Path2D(); paths.set(pn, path); }
        const px = X(p[1]), py = Y(p[2]);
        let linked = false;
        const f = p[5] >= 0 ? lp.get(p[5]) : undefined;
        if (f) {
          linked = true;
          const fx = X(f[1]), fy = Y(f[2]);
          if (vis(px, py) || vis(fx, fy) || crosses(px, py, fx, fy, W, H)) {
            path.moveTo(px, py); path.lineTo(fx, fy); stats.segments++;
          }
        }
        const b = p[6] >= 0 ? lp.get(p[6]) : undefined;
        if (b) {
          linked = true;
          if (b[5] !== p[0]) {
            const bx = X(b[1]), by = Y(b[2]);
            if (vis(px, py) || vis(bx, by) || crosses(px, py, bx, by, W, H)) {
              path.moveTo(bx, by); path.lineTo(px, py); stats.segments++;
            }
          }
        }
        if (!linked && vis(px, py)) { path.moveTo(px - 1.5, py); path.arc(px, py, 1.5, 0, 2 * Math.PI); }
        stats.points++;
      }
      ctx.lineCap = "round";
      ctx.lineJoin = "round";
      for (const [pn, path] of paths) {
        const p = pen(pn);
        ctx.strokeStyle = p.colour;
        ctx.lineWidth = Math.min(4, Math.max(1, p.width_mm * mmPx));
        ctx.stroke(path);
      }
      // -- symbols (spot heights with their heights)
      const size = st.symbol_size_mm * mmPx, cell = size / 15, th = st.text_height_mm * mmPx;
      const labels = [];
      for (const s of t.symbols.values()) {
        const sx = X(s[1]), sy = Y(s[2]);
        if (!vis(sx, sy)) continue;
        const colour = pen(penOf(ext, "symbols", s[4])).colour;
        if (cell < 0.2) {
          ctx.fillStyle = colour;
          ctx.fillRect(sx - 1, sy - 1, 2, 2);
        } else {
          ctx.drawImage(symbolImage(s[4], colour, cell), sx - size / 2, sy - size / 2, size, size);
        }
        stats.symbols++;
        if (s[4] === 0) {
          stats.spot_heights++;
          labels.push([s[3].toFixed(st.height_decimals), sx + size * 2.5 / 15 + 0.4 * th, sy + th / 2, colour]);
        }
      }
      // -- texts (lower-left at the point, cap height th)
      const tcol = pen(penOf(ext, "texts")).colour;
      const fontPx = th / CAP_HEIGHT;
      const readable = fontPx >= 4;
      if (readable) ctx.font = fontPx.toFixed(2) + "px 'DejaVu Sans', 'Liberation Sans', sans-serif";
      for (const [text, lx, ly, colour] of labels) {
        if (!readable) break;
        ctx.fillStyle = colour;
        ctx.fillText(text, lx, ly);
      }
      for (const r of t.texts.values()) {
        const sx = X(r[1]), sy = Y(r[2]);
        if (!vis(sx, sy)) continue;
        stats.texts++;
        if (readable) {
          ctx.fillStyle = tcol;
          ctx.fillText(r[4], sx, sy);
        } else {
          ctx.fillStyle = tcol;
          ctx.fillRect(sx, sy - 1, 3, 1);
        }
      }
    }
    stats.overlays = drawOverlays(X, Y, k, mmPx);
    // -- selection
    if (selected) {
      const r = recordOf(selected);
      if (r) {
        ctx.strokeStyle = "#ff6f00";
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.arc(X(r[1]), Y(r[2]), 9, 0, 2 * Math.PI);
        ctx.stroke();
      }
    }
    // -- the floating mark: a crosshair at the crosshair scale
    const mk = S.status.mark;
    if (mk) {
      const mx = X(mk[0]), my = Y(mk[1]);
      const arm = 6 * MM_PX * (S.display.crosshair || 1);
      ctx.strokeStyle = "#d50000";
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      ctx.moveTo(mx - arm, my); ctx.lineTo(mx - 3, my);
      ctx.moveTo(mx + 3, my); ctx.lineTo(mx + arm, my);
      ctx.moveTo(mx, my - arm); ctx.lineTo(mx, my - 3);
      ctx.moveTo(mx, my + 3); ctx.lineTo(mx, my + arm);
      ctx.stroke();
      ctx.beginPath();
      ctx.arc(mx, my, 1.5, 0, 2 * Math.PI);
      ctx.fillStyle = "#d50000";
      ctx.fill();
      stats.mark = true;
      stats.crosshair_px = arm;
    }
    drawn = stats;
    renderScale();
  }

  function crosses(ax, ay, bx, by, W, H) {
    // a segment whose bounding box overlaps the window (both ends outside)
    return !(Math.max(ax, bx) < 0 || Math.min(ax, bx) > W || Math.max(ay, by) < 0 || Math.min(ay, by) > H);
  }

  function residualExaggeration() {
    let vmax = 0;
    for (const o of S.overlays) if (o.kind === "control" && o.residual) vmax = Math.max(vmax, Math.hypot(o.residual[0], o.residual[1]));
    if (!(vmax > 0)) return 0;
    const e = extent();
    const span = e ? Math.max(e[2] - e[0], e[3] - e[1], 1) : 1000;
    const raw = (0.08 * span) / vmax;
    const p = Math.pow(10, Math.floor(Math.log10(raw)));
    return [1, 2, 5, 10].map((m) => m * p).filter((v) => v <= raw).pop() || p;
  }

  function drawOverlays(X, Y, k, mmPx) {
    let n = 0;
    const legend = [];
    ctx.font = "12px 'DejaVu Sans', 'Liberation Sans', sans-serif";
    const exag = residualExaggeration();
    for (const o of S.overlays) {
      if (o.kind === "area") {
        ctx.beginPath();
        o.ring.forEach((p, i) => (i ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
        ctx.closePath();
        ctx.fillStyle = "rgba(255, 152, 0, 0.25)";
        ctx.fill();
        ctx.strokeStyle = "#ef6c00";
        ctx.lineWidth = 2;
        ctx.stroke();
        let cx = 0, cy = 0;
        for (const p of o.ring) { cx += p[0]; cy += p[1]; }
        cx /= o.ring.length; cy /= o.ring.length;
        label("AREA " + o.area_m2.toFixed(2) + " m\u00b2", X(cx), Y(cy), "#bf360c");
        n++;
      } else if (o.kind === "dhi") {
        const ax = X(o.a[0]), ay = Y(o.a[1]), bx = X(o.b[0]), by = Y(o.b[1]);
        ctx.strokeStyle = "#8e24aa";
        ctx.lineWidth = 2;
        ctx.setLineDash([6, 4]);
        ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke();
        ctx.setLineDash([]);
        for (const [x, y] of [[ax, ay], [bx, by]]) { ctx.beginPath(); ctx.arc(x, y, 3, 0, 2 * Math.PI); ctx.fillStyle = "#8e24aa"; ctx.fill(); }
        const sign = o.dz_m >= 0 ? "+" : "";
        label("DHI " + o.distance_m.toFixed(2) + " m, dZ " + sign + o.dz_m.toFixed(2) + " m", (ax + bx) / 2, (ay + by) / 2 + 18, "#6a1b9a");
        n++;
      } else if (o.kind === "control") {
        const x = X(o.x), y = Y(o.y), r = 6;
        ctx.beginPath();
        ctx.moveTo(x, y - r); ctx.lineTo(x + r * 0.87, y + r / 2); ctx.lineTo(x - r * 0.87, y + r / 2); ctx.closePath();
        ctx.strokeStyle = o.rejected ? "#9e9e9e" : "#c62828";
        ctx.lineWidth = 1.5;
        ctx.stroke();
        if (o.residual && exag) {
          const ex = X(o.x + o.residual[0] * exag), ey = Y(o.y + o.residual[1] * exag);
          arrow(x, y, ex, ey, "#1565c0");
        }
        label(o.id + (o.rejected ? " (rejected)" : ""), x + 8, y - 8, o.rejected ? "#757575" : "#b71c1c");
        n++;
      }
    }
    if (exag) legend.push("residuals \u00d7" + exag + " (blue arrows)");
    $("legend").textContent = legend.join(" \u00b7 ");
    return n;
  }

  function arrow(x0, y0, x1, y1, colour) {
    ctx.strokeStyle = colour;
    ctx.fillStyle = colour;
    ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
    const a = Math.atan2(y1 - y0, x1 - x0), h = 8;
    ctx.beginPath();
    ctx.moveTo(x1, y1);
    ctx.lineTo(x1 - h * Math.cos(a - 0.4), y1 - h * Math.sin(a - 0.4));
    ctx.lineTo(x1 - h * Math.cos(a + 0.4), y1 - h * Math.sin(a + 0.4));
    ctx.closePath();
    ctx.fill();
  }

  function label(text, x, y, colour) {
    const w = ctx.measureText(text).width;
    ctx.fillStyle = "rgba(255,255,255,0.8)";
    ctx.fillRect(x - 2, y - 11, w + 4, 14);
    ctx.fillStyle = colour;
    ctx.fillText(text, x, y);
  }

  // ------------------------------------------------------------------ panels

  function renderPanels(layersChanged) {
    $("title").textContent =
      (S.kind === "session" ? "session on " : S.kind === "orientation" ? "orientation of " : "map ") + (S.meta.id || "");
    document.title = "apygis view: " + (S.meta.id || "");
    if (layersChanged) renderLayers();
    renderEntries();
    renderResults();
    renderStatus();
    renderRecord();
    redraw();
  }

  function renderLayers() {
    const ul = $("layers");
    ul.replaceChildren();
    for (const ext of [...S.layers.keys()].sort()) {
      const t = S.layers.get(ext);
      const li = document.createElement("li");
      const cb = document.createElement("input");
      cb.type = "checkbox";
      cb.checked = !S.hidden.has(ext);
      cb.dataset.layer = ext;
      cb.addEventListener("change", () => {
        if (cb.checked) S.hidden.delete(ext); else S.hidden.add(ext);
        redraw();
      });
      const sw = document.createElement("span");
      sw.className = "swatch";
      const lp = S.layerPens[ext];
      sw.style.background = pen(lp ? lp.lines[0] : 1).colour;
      const name = document.createElement("span");
      name.textContent = (S.meta.id || "") + "." + ext;
      const n = document.createElement("span");
      n.className = "n";
      n.textContent = t.symbols.size + " sym " + t.line_points.size + " pts " + t.texts.size + " txt";
      li.append(cb, sw, name, n);
      ul.append(li);
    }
  }

  function entryText(e) {
    const [n, what, ext, table, num, extra] = e;
    if (what === "undone") return n + ": undo (layer " + ext + ")";
    if (what === "linked") return n + ": line point " + num + " joined to " + extra.target + " in " + ext + " (" + extra.how + ")";
    return n + ": " + WORDS[table] + " " + num + " " + what + " in " + ext;
  }

  function renderEntries() {
    const ol = $("entries");
    $("entrycount").textContent = S.entries.length ? "(" + S.entries.length + ")" : "";
    $("entrybox").hidden = S.kind !== "session";
    // append only what is new (entries are never taken back: UNDO is an entry)
    if (ol.childElementCount > S.entries.length) ol.replaceChildren();
    for (let i = ol.childElementCount; i < S.entries.length; i++) {
      const e = S.entries[i];
      const li = document.createElement("li");
      li.textContent = entryText(e);
      li.className = e[1];
      if (e[3] && e[4] !== null) li.addEventListener("click", () => select({ ext: e[2], table: e[3], num: e[4] }, true));
      ol.append(li);
    }
    ol.scrollTop = ol.scrollHeight;
  }

  function renderResults() {
    const ul = $("results");
    const res = S.overlays.filter((o) => o.kind === "area" || o.kind === "dhi");
    const ctl = S.overlays.filter((o) => o.kind === "control");
    $("resultbox").hidden = !res.length && !ctl.length;
    ul.replaceChildren();
    for (const o of res) {
      const li = document.createElement("li");
      if (o.kind === "area")
        li.textContent = "AREA " + o.area_m2.toFixed(2) + " m\u00b2, perimeter " + o.perimeter_m.toFixed(2) + " m, " + o.points.length + " points (" + (o.clockwise ? "clockwise" : "counter-clockwise") + ")";
      else
        li.textContent = "DHI " + o.distance_m.toFixed(2) + " m, dZ " + (o.dz_m >= 0 ? "+" : "") + o.dz_m.toFixed(2) + " m, " + o.inclination_deg.toFixed(3) + "\u00b0";
      ul.append(li);
    }
    for (const o of ctl) {
      const li = document.createElement("li");
      const v = o.residual ? Math.hypot(o.residual[0], o.residual[1]).toFixed(3) + " m" : "rejected";
      li.textContent = "control " + o.id + ": " + v;
      ul.append(li);
    }
  }

  function renderStatus() {
    const s = S.status || {};
    $("mode").textContent = s.mode ? "[" + s.mode + "] " + (S.meta.id || "") + "." + s.layer + " " + (s.prompt || "") : (S.kind === "session" ? "" : "view only");
    const c = s.counts;
    $("counts").textContent = c ? c.symbols + " sym " + c.line_points + " pts " + c.texts + " txt" : "";
    $("markxyz").textContent = s.mark ? "mark " + s.mark.map((v) => v.toFixed(2)).join(" ") : "";
    const last = S.messages.length ? S.messages[S.messages.length - 1] : "";
    $("message").textContent = S.ended && S.kind === "session" ? "session ended. " + last : last;
    const conn = $("conn");
    conn.textContent = connected ? (S.ended && S.kind === "session" ? "ended" : "live") : "disconnected";
    conn.className = "conn " + (connected ? (S.ended && S.kind === "session" ? "ended" : "on") : "off");
    if (s.mark) redraw();
  }

  function renderScale() {
    const scale = S.meta.scale || 1000;
    $("scale").textContent =
      "display " + V.factor.toPrecision(3) + "x (1:" + Math.round(scale / V.factor) + ")" +
      (S.kind === "session" ? " \u00b7 PROCEED factor " + S.display.scale + "x, crosshair " + S.display.crosshair + "x" : "");
    $("factor1").hidden = S.kind !== "session";
    $("followbox").hidden = S.kind !== "session";
  }

  function fmt(v) { return v < 0 ? "\u2014" : String(v); }

  function renderRecord() {
    const box = $("record");
    const r = selected && recordOf(selected);
    if (!r) {
      box.className = "muted";
      box.textContent = "click a symbol, line point or text";
      return;
    }
    box.className = "";
    const rows = [
      ["layer", (S.meta.id || "") + "." + selected.ext],
      [WORDS[selected.table], String(r[0])],
    ];
    if (selected.table === "symbols") {
      const s = S.symbols[String(r[4])];
      rows.push(["code", String(r[4]).padStart(2, "0") + (s ? " " + s.name : r[4] === 0 ? " spot height" : "")]);
    } else if (selected.table === "line_points") {
      rows.push(["line code", String(r[4]).padStart(2, "0")]);
      rows.push(["forward", fmt(r[5])], ["backward", fmt(r[6])], ["side 1", fmt(r[7])], ["side 2", fmt(r[8])]);
    } else {
      rows.push(["text", r[4]]);
    }
    rows.push(["X", r[1].toFixed(3)], ["Y", r[2].toFixed(3)], ["Z", r[3].toFixed(3)]);
    const table = document.createElement("table");
    for (const [k, v] of rows) {
      const tr = document.createElement("tr");
      const a = document.createElement("td"), b = document.createElement("td");
      a.textContent = k;
      b.textContent = v;
      tr.append(a, b);
      table.append(tr);
    }
    table.id = "recordtable";
    box.replaceChildren(table);
  }

  function select(sel, centre) {
    selected = sel;
    const r = sel && recordOf(sel);
    if (r && centre) placeAt(r[1], r[2]);
    renderRecord();
    redraw();
  }

  function pick(px, py) {
    let best = null, bestD = HIT_PX;
    for (const [ext, t] of S.layers) {
      if (S.hidden.has(ext)) continue;
      for (const name of TABLES)
        for (const r of t[name].values()) {
          const [sx, sy] = toScreen(r[1], r[2]);
          const d = Math.hypot(sx - px, sy - py);
          if (d < bestD || (d === bestD && best && name === "symbols")) { bestD = d; best = { ext, table: name, num: r[0] }; }
        }
    }
    return best;
  }

  // ------------------------------------------------------------------ input

  let drag = null;
  canvas.addEventListener("pointerdown", (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, cx: V.cx, cy: V.cy, moved: false };
    canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener("pointermove", (ev) => {
    const rect = canvas.getBoundingClientRect();
    const [gx, gy] = toGround(ev.clientX - rect.left, ev.clientY - rect.top);
    const crs = S.meta.crs ? S.meta.crs + (S.meta.crs_name ? " (" + S.meta.crs_name + ")" : "") : "no CRS";
    $("readout").textContent = "X " + gx.toFixed(2) + "  Y " + gy.toFixed(2) + "  " + crs;
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
    if (drag.moved) {
      const k = pxPerM();
      V.cx = drag.cx - dx / k;
      V.cy = drag.cy + dy / k;
      redraw();
    }
  });
  canvas.addEventListener("pointerup", (ev) => {
    if (drag && !drag.moved) {
      const rect = canvas.getBoundingClientRect();
      select(pick(ev.clientX - rect.left, ev.clientY - rect.top), false);
    }
    drag = null;
  });
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const rect = canvas.getBoundingClientRect();
    zoomAbout(ev.clientX - rect.left, ev.clientY - rect.top, Math.pow(1.0015, -ev.deltaY));
  }, { passive: false });
  $("fit").addEventListener("click", fit);
  $("zoomin").addEventListener("click", () => zoomAbout(canvas.clientWidth / 2, canvas.clientHeight / 2, 1.5));
  $("zoomout").addEventListener("click", () => zoomAbout(canvas.clientWidth / 2, canvas.clientHeight / 2, 1 / 1.5));
  $("factor1").addEventListener("click", applyDisplayFactor);
  $("follow").addEventListener("change", (ev) => { V.follow = ev.target.checked; });
  window.addEventListener("resize", () => { symCache = new Map(); redraw(); });

  // ------------------------------------------------------------------ connection

  function connect() {
    const base = location.pathname.replace(/[^/]*$/, "");
    ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + base + "ws");
    ws.onopen = () => { connected = true; renderStatus(); };
    ws.onmessage = (ev) => {
      const m = JSON.parse(ev.data);
      if (m.t === "state") {
        log.states++;
        log.received.push({ t: "state", seq: m.seq, entries: (m.entries || []).length });
        loadState(m);
      } else if (m.t === "delta") {
        log.deltas++;
        log.received.push({ t: "delta", seq: m.seq, entries: (m.entries || []).map((e) => e[0]) });
        applyDelta(m);
      } else if (m.t === "status") {
        log.statuses++;
        applyStatus(m);
      }
    };
    ws.onclose = () => {
      connected = false;
      renderStatus();
      setTimeout(connect, 1000);
    };
  }

  // ------------------------------------------------------------------ the hook

  function counts() {
    const out = {};
    for (const [ext, t] of S.layers) out[ext] = { symbols: t.symbols.size, line_points: t.line_points.size, texts: t.texts.size };
    return out;
  }
  function records() {
    const out = {};
    for (const [ext, t] of S.layers) {
      out[ext] = {};
      for (const name of TABLES) out[ext][name] = [...t[name].values()].sort((a, b) => a[0] - b[0]);
    }
    return out;
  }

  window.apygisView = Object.freeze({
    connected: () => connected,
    seq: () => S.seq,
    kind: () => S.kind,
    map: () => S.meta,
    counts,
    records,
    entries: () => S.entries.map((e) => e.slice()),
    received: () => log.received.slice(),
    messageCounts: () => ({ states: log.states, deltas: log.deltas, statuses: log.statuses }),
    status: () => Object.assign({}, S.status),
    display: () => Object.assign({}, S.display),
    ended: () => S.ended,
    overlays: () => S.overlays.slice(),
    messages: () => S.messages.slice(),
    view: () => ({ cx: V.cx, cy: V.cy, factor: V.factor, pxPerM: pxPerM() }),
    drawn: () => Object.assign({}, drawn),
    selected: () => (selected ? Object.assign({}, selected) : null),
    toScreen: (x, y) => toScreen(x, y),
    canvasOrigin: () => { const r = canvas.getBoundingClientRect(); return [r.left, r.top]; },
    hideLayer: (ext, hidden) => { if (hidden) S.hidden.add(ext); else S.hidden.delete(ext); renderLayers(); redraw(); },
    fit,
    drawNow: () => { if (frame) { cancelAnimationFrame(frame); } draw(); return Object.assign({}, drawn); },
  });

  connect();
})();
