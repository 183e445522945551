/* gpsdr HTML report: draws the track from the inline JSON on canvases.
 * Map in the local east/north frame (metres, north up): pan by dragging, zoom with the
 * wheel, fit with a double-click; hover shows the nearest epoch or fix.  Time panels
 * share one time axis (minutes since the start).  An optional OpenStreetMap base map is
 * drawn under the track through the affine local -> Web Mercator fit in the data.
 * When drawing is done, #status gets data-state="done" and the counts drawn; a
 * JavaScript error sets data-state="error".  A URL hash "#probe=K" hovers line point K,
 * "#zoom=F" zooms the map F times, "#basemap=1" ticks the base map (used by the tests). */
(function () {
  "use strict";
  var statusEl = document.getElementById("status");
  function fail(msg) {
    statusEl.setAttribute("data-state", "error");
    statusEl.textContent = "JavaScript error: " + msg;
  }
  window.addEventListener("error", function (ev) { fail(ev.message || String(ev)); });

  var D = JSON.parse(document.getElementById("gpsdr-data").textContent);
  var L = D.line, F = D.fixes;
  var NL = L.t.length, NF = F.t.length;
  var DPR = window.devicePixelRatio || 1;
  var QUALITY_COLOURS = ["#1a9641", "#7ac143", "#c9b400", "#f28e2b", "#e15759", "#8b0000"];
  var QUALITY_NAMES = ["1 best", "2", "3", "4", "5", "6 worst"];
  // a perceptual ramp (dark blue -> teal -> yellow -> red) sampled at 9 stops
  var RAMP = ["#2c3e9e", "#2a6fb8", "#1f9bb5", "#2fb58f", "#7ac143", "#c9c31e", "#f2a516",
    "#ec6a1c", "#c5221f"];
  var N_BINS = RAMP.length;
  var STATE_NAMES = ["no fix", "GNSS fix used", "GNSS fix down-weighted", "GNSS fix rejected",
    "GNSS outage"];
  var layers = { basemap: false, reference: true, fixes: true, downweighted: true,
    rejected: true, outages: true, fused: true };
  var colourBy = D.colour_by;
  var hover = null;          // {kind: "line"|"fix", i: index}
  var visiblePoints = 0;

  // ------------------------------------------------------------------ helpers
  function fmt(v, digits, unit) {
    if (v === null || v === undefined || !isFinite(v)) { return "-"; }
    return v.toFixed(digits) + (unit ? " " + unit : "");
  }
  function utc(tSec) {
    var d = new Date(D.start_ms + tSec * 1000);
    var iso = d.toISOString();
    return iso.slice(0, 10) + " " + iso.slice(11, 22) + " UTC";
  }
  function el(tag, attrs, text) {
    var x = document.createElement(tag);
    for (var k in attrs) { if (Object.prototype.hasOwnProperty.call(attrs, k)) { x.setAttribute(k, attrs[k]); } }
    if (text !== undefined) { x.textContent = text; }
    return x;
  }
  function lowerBound(arr, v) {  // first index with arr[i] >= v (arr ascending)
    var lo = 0, hi = arr.length;
    while (lo < hi) { var mid = (lo + hi) >> 1; if (arr[mid] < v) { lo = mid + 1; } else { hi = mid; } }
    return lo;
  }
  function nearestByTime(arr, t) {
    var i = lowerBound(arr, t);
    if (i >= arr.length) { return arr.length - 1; }
    if (i > 0 && t - arr[i - 1] < arr[i] - t) { return i - 1; }
    return i;
  }
  function niceStep(span, target) {
    var raw = span / Math.max(target, 1);
    var p = Math.pow(10, Math.floor(Math.log10(raw)));
    var m = raw / p;
    return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
  }
  function sizeCanvas(c) {
    var r = c.getBoundingClientRect();
    var w = Math.max(1, Math.round(r.width)), h = Math.max(1, Math.round(r.height));
    if (c.width !== Math.round(w * DPR) || c.height !== Math.round(h * DPR)) {
      c.width = Math.round(w * DPR); c.height = Math.round(h * DPR);
    }
    var ctx = c.getContext("2d");
    ctx.setTransform(DPR, 0, 0, DPR, 0, 0);
    return { ctx: ctx, w: w, h: h };
  }

  // ------------------------------------------------------------------ colours
  var sigmaRange = (function () {
    var v = [];
    for (var i = 0; i < NL; i++) { if (L.sigma[i] > 0) { v.push(Math.log10(L.sigma[i])); } }
    if (!v.length) { return [0, 1]; }
    v.sort(function (a, b) { return a - b; });
    var lo = v[Math.floor(0.02 * (v.length - 1))], hi = v[Math.floor(0.98 * (v.length - 1))];
    if (hi - lo < 0.3) { lo -= 0.15; hi += 0.15; }
    return [lo, hi];
  })();
  var speedMax = (function () {
    var m = 1;
    for (var i = 0; i < NL; i++) { if (L.speed[i] > m) { m = L.speed[i]; } }
    return m;
  })();
  function binOf(i) {  // colour bin of line point i: index into colours()
    if (colourBy === "quality") {
      var q = L.quality[i];
      return q === null ? -1 : Math.min(5, Math.max(0, Math.round(q) - 1));
    }
    var x;
    if (colourBy === "speed") { x = L.speed[i] === null ? NaN : L.speed[i] / speedMax; }
    else { x = L.sigma[i] > 0 ? (Math.log10(L.sigma[i]) - sigmaRange[0]) / (sigmaRange[1] - sigmaRange[0]) : NaN; }
    if (!isFinite(x)) { return -1; }
    return Math.min(N_BINS - 1, Math.max(0, Math.floor(x * N_BINS)));
  }
  function colours() { return colourBy === "quality" ? QUALITY_COLOURS : RAMP; }
  var bins = new Int8Array(NL);
  function computeBins() { for (var i = 0; i < NL; i++) { bins[i] = binOf(i); } }

  function drawLegend() {
    var lg = document.getElementById("legend");
    lg.textContent = "";
    if (colourBy === "quality") {
      lg.appendChild(el("div", {}, "fused track: quality"));
      for (var q = 0; q < 6; q++) {
        var row = el("div", { "class": "row" });
        var sw = el("i"); sw.style.background = QUALITY_COLOURS[q];
        row.appendChild(sw); row.appendChild(el("span", {}, QUALITY_NAMES[q]));
        lg.appendChild(row);
      }
    } else {
      var isSigma = colourBy === "sigma";
      lg.appendChild(el("div", {}, isSigma ? "fused track: horizontal 1-sigma (m)" : "fused track: speed (m/s)"));
      var bar = el("div", { "class": "bar" });
      bar.style.background = "linear-gradient(to right," + RAMP.join(",") + ")";
      lg.appendChild(bar);
      var ticks = el("div", { "class": "ticks" });
      var lo = isSigma ? Math.pow(10, sigmaRange[0]) : 0, hi = isSigma ? Math.pow(10, sigmaRange[1]) : speedMax;
      var mid = isSigma ? Math.pow(10, 0.5 * (sigmaRange[0] + sigmaRange[1])) : 0.5 * speedMax;
      [lo, mid, hi].forEach(function (v) { ticks.appendChild(el("span", {}, v < 10 ? v.toFixed(2) : v.toFixed(0))); });
      lg.appendChild(ticks);
    }
    var extra = [["#aaaaaa", "GNSS fixes"], ["#111111", "reference"], ["#f28e2b", "GNSS outage"]];
    extra.forEach(function (x) {
      if (x[1] === "reference" && !D.reference) { return; }
      var row = el("div", { "class": "row" });
      var sw = el("i"); sw.style.background = x[0];
      row.appendChild(sw); row.appendChild(el("span", {}, x[1])); lg.appendChild(row);
    });
  }

  // ------------------------------------------------------------------ map view
  var mapCanvas = document.getElementById("map");
  var view = { cx: 0, cy: 0, scale: 1, w: 1, h: 1 };  // scale: px per metre
  var extent = (function () {
    var x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    function add(es, ns) {
      for (var i = 0; i < es.length; i++) {
        var e = es[i], n = ns[i];
        if (e === null || n === null) { continue; }
        if (e < x0) { x0 = e; } if (e > x1) { x1 = e; } if (n < y0) { y0 = n; } if (n > y1) { y1 = n; }
      }
    }
    add(L.e, L.n); add(F.e, F.n);
    if (!isFinite(x0)) { x0 = y0 = -10; x1 = y1 = 10; }
    return [x0, x1, y0, y1];
  })();
  function fitView() {
    var s = sizeCanvas(mapCanvas);
    view.w = s.w; view.h = s.h;
    var dx = Math.max(extent[1] - extent[0], 10), dy = Math.max(extent[3] - extent[2], 10);
    view.scale = 0.92 * Math.min(view.w / dx, view.h / dy);
    view.cx = 0.5 * (extent[0] + extent[1]); view.cy = 0.5 * (extent[2] + extent[3]);
  }
  function px(e) { return view.w / 2 + (e - view.cx) * view.scale; }
  function py(n) { return view.h / 2 - (n - view.cy) * view.scale; }
  function toEN(x, y) { return [view.cx + (x - view.w / 2) / view.scale, view.cy - (y - view.h / 2) / view.scale]; }

  // ------------------------------------------------------------------ base map
  var tiles = {}, tileErrors = 0, tileLoads = 0;
  var A = D.mercator;  // x = a e + b n + c, y = d e + f n + g (Web Mercator metres)
  var HALF = 20037508.342789244;
  function drawBasemap(ctx) {
    var note = document.getElementById("basemap-note");
    if (!A) { note.textContent = "no base map: the track has no lat/lon"; return; }
    if (navigator.onLine === false) { note.textContent = "base map not loaded: offline"; return; }
    var det = A[0] * A[4] - A[1] * A[3];
    var k = Math.sqrt(Math.abs(det));  // Mercator metres per local metre
    var z = Math.round(Math.log2(156543.03392804097 / (k / view.scale)));
    z = Math.max(0, Math.min(19, z));
    var ntile = Math.pow(2, z), tileM = 2 * HALF / ntile;
    var xs = [], ys = [];
    [[0, 0], [view.w, 0], [0, view.h], [view.w, view.h]].forEach(function (p) {
      var en = toEN(p[0], p[1]);
      xs.push(A[0] * en[0] + A[1] * en[1] + A[2]); ys.push(A[3] * en[0] + A[4] * en[1] + A[5]);
    });
    var tx0 = Math.floor((Math.min.apply(null, xs) + HALF) / tileM), tx1 = Math.floor((Math.max.apply(null, xs) + HALF) / tileM);
    var ty0 = Math.floor((HALF - Math.max.apply(null, ys)) / tileM), ty1 = Math.floor((HALF - Math.min.apply(null, ys)) / tileM);
    if ((tx1 - tx0 + 1) * (ty1 - ty0 + 1) > 64) { return; }
    // inverse of the affine: local (e, n) from Mercator (x, y)
    var ia = A[4] / det, ib = -A[1] / det, id = -A[3] / det, ie = A[0] / det;
    ctx.save();
    ctx.globalAlpha = 0.55;
    for (var tx = tx0; tx <= tx1; tx++) {
      for (var ty = ty0; ty <= ty1; ty++) {
        if (ty < 0 || ty >= ntile) { continue; }
        var txw = ((tx % ntile) + ntile) % ntile;
        var key = z + "/" + txw + "/" + ty;
        var img = tiles[key];
        if (!img) {
          img = new Image();
          img.onload = function () { tileLoads++; scheduleMap(); };
          img.onerror = function () {
            tileErrors++;
            if (!tileLoads) { document.getElementById("basemap-note").textContent = "base map tiles could not be loaded (offline?)"; }
          };
          img.src = D.tiles.url.replace("{z}", z).replace("{x}", txw).replace("{y}", ty);
          tiles[key] = img;
        }
        if (!img.complete || !img.naturalWidth) { continue; }
        // tile pixel (u, v) -> Mercator -> local -> canvas pixel, as one affine
        var x0 = tx * tileM - HALF, y0 = HALF - ty * tileM, r = tileM / 256;
        // local = Ainv (merc - c): merc = (x0 + r u, y0 - r v)
        var ex = ia * r, ey = -ib * r, nx = id * r, ny = -ie * r;
        var e0 = ia * (x0 - A[2]) + ib * (y0 - A[5]), n0 = id * (x0 - A[2]) + ie * (y0 - A[5]);
        var s = view.scale;
        ctx.setTransform(DPR * s * ex, -DPR * s * nx, DPR * s * ey, -DPR * s * ny,
          DPR * px(e0), DPR * py(n0));
        ctx.drawImage(img, 0, 0, 256, 256);
      }
    }
    ctx.restore();
    document.getElementById("attribution").textContent = D.tiles.attribution;
  }

  // ------------------------------------------------------------------ map drawing
  function inView(x, y, pad) { return x > -pad && x < view.w + pad && y > -pad && y < view.h + pad; }
  function drawMap() {
    var s = sizeCanvas(mapCanvas);
    view.w = s.w; view.h = s.h;
    var ctx = s.ctx;
    ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, view.w, view.h);
    document.getElementById("attribution").textContent = "";
    document.getElementById("basemap-note").textContent = "";
    if (layers.basemap) { drawBasemap(ctx); }
    drawGrid(ctx);
    var i, x, y;
    if (layers.reference && D.reference) {
      ctx.strokeStyle = "#111111"; ctx.lineWidth = 1; ctx.beginPath();
      var R = D.reference, pen = false;
      for (i = 0; i < R.e.length; i++) {
        if (R.e[i] === null) { pen = false; continue; }
        x = px(R.e[i]); y = py(R.n[i]);
        if (pen) { ctx.lineTo(x, y); } else { ctx.moveTo(x, y); pen = true; }
      }
      ctx.stroke();
    }
    if (layers.fixes) {
      ctx.fillStyle = "#a8a8a8"; ctx.beginPath();
      for (i = 0; i < NF; i++) {
        if (F.state[i] !== 1) { continue; }
        x = px(F.e[i]); y = py(F.n[i]);
        if (inView(x, y, 3)) { ctx.rect(x - 1.25, y - 1.25, 2.5, 2.5); }
      }
      ctx.fill();
    }
    if (layers.outages) {
      ctx.strokeStyle = "rgba(242,142,43,0.7)"; ctx.lineWidth = 8; ctx.lineCap = "round"; ctx.beginPath();
      for (i = 1; i < NL; i++) {
        if (L.state[i] !== 4 || L.state[i - 1] !== 4) { continue; }
        ctx.moveTo(px(L.e[i - 1]), py(L.n[i - 1])); ctx.lineTo(px(L.e[i]), py(L.n[i]));
      }
      ctx.stroke();
    }
    visiblePoints = 0;
    if (layers.fused) {
      var cols = colours(), paths = [];
      for (var b = 0; b <= cols.length; b++) { paths.push(new Path2D()); }
      for (i = 0; i < NL; i++) {
        x = px(L.e[i]); y = py(L.n[i]);
        var vis = inView(x, y, 0);
        if (vis) { visiblePoints++; }
        if (i === 0) { continue; }
        var x0 = px(L.e[i - 1]), y0 = py(L.n[i - 1]);
        if (!vis && !inView(x0, y0, 0) && !segmentCrosses(x0, y0, x, y)) { continue; }
        var p = paths[bins[i - 1] < 0 ? cols.length : bins[i - 1]];
        p.moveTo(x0, y0); p.lineTo(x, y);
      }
      ctx.lineWidth = 2.2; ctx.lineCap = "round"; ctx.lineJoin = "round";
      for (b = 0; b <= cols.length; b++) {
        ctx.strokeStyle = b < cols.length ? cols[b] : "#777777";
        ctx.stroke(paths[b]);
      }
    }
    if (layers.downweighted) {
      ctx.strokeStyle = "#e69500"; ctx.lineWidth = 1.4; ctx.beginPath();
      for (i = 0; i < NF; i++) {
        if (F.state[i] !== 2) { continue; }
        x = px(F.e[i]); y = py(F.n[i]);
        if (inView(x, y, 5)) { ctx.moveTo(x + 3.5, y); ctx.arc(x, y, 3.5, 0, 2 * Math.PI); }
      }
      ctx.stroke();
    }
    if (layers.rejected) {
      ctx.strokeStyle = "#d62728"; ctx.lineWidth = 1.5; ctx.beginPath();
      for (i = 0; i < NF; i++) {
        if (F.state[i] !== 3) { continue; }
        x = px(F.e[i]); y = py(F.n[i]);
        if (inView(x, y, 5)) { ctx.moveTo(x - 3, y - 3); ctx.lineTo(x + 3, y + 3); ctx.moveTo(x - 3, y + 3); ctx.lineTo(x + 3, y - 3); }
      }
      ctx.stroke();
    }
    if (layers.outages) {
      ctx.font = "11px sans-serif"; ctx.fillStyle = "#c45f00";
      D.outages.forEach(function (o) {
        if (!o.labelled) { return; }
        var xa = px(o.e0), ya = py(o.n0), xb = px(o.e1), yb = py(o.n1);
        ctx.beginPath(); ctx.moveTo(xa - 4, ya - 5); ctx.lineTo(xa + 5, ya); ctx.lineTo(xa - 4, ya + 5); ctx.closePath(); ctx.fill();
        ctx.fillRect(xb - 4, yb - 4, 8, 8);
        ctx.fillText(o.duration_s.toFixed(0) + " s outage", xb + 7, yb - 6);
      });
    }
    if (NL) {  // start
      ctx.fillStyle = "#2ca02c"; ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 1.5;
      ctx.beginPath(); ctx.arc(px(L.e[0]), py(L.n[0]), 5.5, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
    }
    drawScaleBar(ctx);
    if (hover) {
      var he = hover.kind === "fix" ? F.e[hover.i] : L.e[hover.i];
      var hn = hover.kind === "fix" ? F.n[hover.i] : L.n[hover.i];
      ctx.strokeStyle = "#000000"; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.arc(px(he), py(hn), 7, 0, 2 * Math.PI); ctx.stroke();
    }
  }
  function segmentCrosses(x0, y0, x1, y1) {  // a segment with both ends out of view may still cross it
    return !((x0 < 0 && x1 < 0) || (x0 > view.w && x1 > view.w) || (y0 < 0 && y1 < 0) || (y0 > view.h && y1 > view.h));
  }
  function drawGrid(ctx) {
    var step = niceStep(view.w / view.scale, 6);
    var a = toEN(0, view.h), b = toEN(view.w, 0);
    ctx.strokeStyle = layers.basemap ? "rgba(0,0,0,0.08)" : "#eeeeee"; ctx.lineWidth = 1; ctx.beginPath();
    for (var e = Math.ceil(a[0] / step) * step; e <= b[0]; e += step) { ctx.moveTo(px(e), 0); ctx.lineTo(px(e), view.h); }
    for (var n = Math.ceil(a[1] / step) * step; n <= b[1]; n += step) { ctx.moveTo(0, py(n)); ctx.lineTo(view.w, py(n)); }
    ctx.stroke();
  }
  function drawScaleBar(ctx) {
    var m = niceStep(120 / view.scale, 1);
    var len = m * view.scale, x = 12, y = view.h - 12;
    ctx.fillStyle = "rgba(255,255,255,0.8)"; ctx.fillRect(x - 6, y - 30, Math.max(len + 60, 170), 38);
    ctx.strokeStyle = "#222"; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(x, y - 4); ctx.lineTo(x, y); ctx.lineTo(x + len, y); ctx.lineTo(x + len, y - 4); ctx.stroke();
    ctx.fillStyle = "#222"; ctx.font = "11px sans-serif";
    ctx.fillText(m >= 1000 ? (m / 1000) + " km" : m + " m", x + len + 6, y);
    ctx.fillText("N \u2191  local east/north frame", x, y - 18);
  }

  var mapQueued = false;
  function scheduleMap() {
    if (mapQueued) { return; }
    mapQueued = true;
    requestAnimationFrame(function () { mapQueued = false; drawMap(); });
  }

  // ------------------------------------------------------------------ map interaction
  var drag = null;
  mapCanvas.addEventListener("pointerdown", function (ev) {
    drag = { x: ev.clientX, y: ev.clientY, cx: view.cx, cy: view.cy };
    mapCanvas.setPointerCapture(ev.pointerId); mapCanvas.classList.add("dragging");
  });
  mapCanvas.addEventListener("pointerup", function (ev) {
    drag = null; mapCanvas.releasePointerCapture(ev.pointerId); mapCanvas.classList.remove("dragging");
  });
  mapCanvas.addEventListener("pointermove", function (ev) {
    if (drag) {
      view.cx = drag.cx - (ev.clientX - drag.x) / view.scale;
      view.cy = drag.cy + (ev.clientY - drag.y) / view.scale;
      hideTooltip(); scheduleMap(); return;
    }
    var r = mapCanvas.getBoundingClientRect();
    hoverMapAt(ev.clientX - r.left, ev.clientY - r.top, ev.clientX, ev.clientY);
  });
  mapCanvas.addEventListener("pointerleave", function () { if (!drag) { setHover(null); } });
  mapCanvas.addEventListener("wheel", function (ev) {
    ev.preventDefault();
    var r = mapCanvas.getBoundingClientRect();
    zoomMap(Math.exp(-ev.deltaY * 0.0015), ev.clientX - r.left, ev.clientY - r.top);
  }, { passive: false });
  mapCanvas.addEventListener("dblclick", function () { fitView(); scheduleMap(); });
  function zoomMap(f, x, y) {
    var before = toEN(x, y);
    view.scale = Math.min(Math.max(view.scale * f, 1e-4), 500);
    var after = toEN(x, y);
    view.cx += before[0] - after[0]; view.cy += before[1] - after[1];
    scheduleMap();
  }
  function hoverMapAt(x, y, cx, cy) {
    var best = null, bd = 144;  // 12 px
    var i, dx, dy, d;
    if (layers.fused) {
      for (i = 0; i < NL; i++) {
        dx = px(L.e[i]) - x; dy = py(L.n[i]) - y; d = dx * dx + dy * dy;
        if (d < bd) { bd = d; best = { kind: "line", i: i }; }
      }
    }
    var fd = Math.min(bd, 64);  // fixes: 8 px, and only when nearer than the line
    for (i = 0; i < NF; i++) {
      var st = F.state[i];
      if ((st === 1 && !layers.fixes) || (st === 2 && !layers.downweighted) || (st === 3 && !layers.rejected)) { continue; }
      dx = px(F.e[i]) - x; dy = py(F.n[i]) - y; d = dx * dx + dy * dy;
      if (d < fd) { fd = d; best = { kind: "fix", i: i }; }
    }
    setHover(best, cx, cy);
  }

  // ------------------------------------------------------------------ tooltip
  var tip = document.getElementById("tooltip");
  function tooltipText(h) {
    var lines = [];
    if (h.kind === "fix") {
      lines.push("GNSS fix  " + utc(F.t[h.i]));
      lines.push("state: " + STATE_NAMES[F.state[h.i]]);
      if (F.weight) { lines.push("weight " + fmt(F.weight[h.i], 3)); }
      lines.push("PDOP " + fmt(F.pdop[h.i], 2));
      var k = nearestByTime(L.t, F.t[h.i]);
      lines.push("fused speed " + fmt(L.speed[k], 2, "m/s") + ", sigma " + fmt(L.sigma[k], 2, "m"));
      return lines.join("\n");
    }
    var i = h.i;
    lines.push(utc(L.t[i]) + "  (t+" + L.t[i].toFixed(1) + " s)");
    lines.push("speed " + fmt(L.speed[i], 2, "m/s") + " (" + fmt(L.speed[i] === null ? null : 3.6 * L.speed[i], 1, "km/h") + ")");
    lines.push("sigma " + fmt(L.sigma[i], 3, "m") + " (horizontal 1-sigma)");
    lines.push("PDOP " + fmt(L.pdop[i], 2));
    if (L.quality) { lines.push("quality " + fmt(L.quality[i], 0) + " (1 best .. 6 worst)"); }
    if (L.sep) { lines.push("separation " + fmt(L.sep[i], 3, "m") + " (forward/backward)"); }
    if (L.err) { lines.push("error " + fmt(L.err[i], 3, "m") + " (against the reference)"); }
    lines.push(L.state[i] === 4 ? "in a GNSS outage (dead reckoning)" : "GNSS fixes available");
    return lines.join("\n");
  }
  function setHover(h, cx, cy) {
    var same = (h === null && hover === null) || (h && hover && h.kind === hover.kind && h.i === hover.i);
    hover = h;
    if (!h) { hideTooltip(); } else {
      tip.textContent = tooltipText(h);
      tip.hidden = false;
      if (cx !== undefined) {
        var tw = tip.offsetWidth, th = tip.offsetHeight;
        tip.style.left = Math.min(cx + 14, window.innerWidth - tw - 4) + "px";
        tip.style.top = Math.min(cy + 14, window.innerHeight - th - 4) + "px";
      }
    }
    if (!same) {
      cursorT = h ? (h.kind === "fix" ? F.t[h.i] : L.t[h.i]) : null;
      scheduleMap(); schedulePanels();
    }
  }
  function hideTooltip() { tip.hidden = true; }

  // ------------------------------------------------------------------ time panels
  var S = D.series;
  var tSpan = [0, Math.max(D.duration_s, 1)];
  var tv = [tSpan[0], tSpan[1]];  // visible time range (s)
  var cursorT = null;
  var panels = [];
  var PAD = { l: 52, r: 10, t: 20, b: 22 };
  function seriesOf(item) {
    if (item.kind === "dots") { var d = D.dots[item.src]; return { t: d.t, v: d.v }; }
    return { t: S.t, v: S[item.src] };
  }
  function buildPanels() {
    var box = document.getElementById("panels");
    D.panels.forEach(function (spec, k) {
      var div = el("div", { "class": "panel" + (k === 0 ? " main" : ""), "data-panel": spec.id });
      var c = el("canvas", { "aria-label": spec.title });
      div.appendChild(c); box.appendChild(div);
      var p = { spec: spec, canvas: c };
      panels.push(p);
      var pdrag = null;
      c.addEventListener("pointerdown", function (ev) { pdrag = { x: ev.clientX, tv: [tv[0], tv[1]] }; c.setPointerCapture(ev.pointerId); });
      c.addEventListener("pointerup", function (ev) { pdrag = null; c.releasePointerCapture(ev.pointerId); });
      c.addEventListener("pointermove", function (ev) {
        var r = c.getBoundingClientRect(), w = r.width - PAD.l - PAD.r;
        if (pdrag) {
          var dt = (ev.clientX - pdrag.x) / w * (pdrag.tv[1] - pdrag.tv[0]);
          setTimeView(pdrag.tv[0] - dt, pdrag.tv[1] - dt); return;
        }
        var t = tv[0] + (ev.clientX - r.left - PAD.l) / w * (tv[1] - tv[0]);
        hoverPanelAt(p, t, ev.clientX, ev.clientY);
      });
      c.addEventListener("pointerleave", function () { if (!pdrag) { setHover(null); } });
      c.addEventListener("wheel", function (ev) {
        ev.preventDefault();
        var r = c.getBoundingClientRect(), w = r.width - PAD.l - PAD.r;
        var t = tv[0] + (ev.clientX - r.left - PAD.l) / w * (tv[1] - tv[0]);
        var f = Math.exp(ev.deltaY * 0.0015);
        setTimeView(t - (t - tv[0]) * f, t + (tv[1] - t) * f);
      }, { passive: false });
      c.addEventListener("dblclick", function () { setTimeView(tSpan[0], tSpan[1]); });
    });
  }
  function setTimeView(a, b) {
    var minSpan = 1.0;
    if (b - a < minSpan) { var m = 0.5 * (a + b); a = m - minSpan / 2; b = m + minSpan / 2; }
    var span = Math.min(b - a, tSpan[1] - tSpan[0]);
    if (a < tSpan[0]) { a = tSpan[0]; b = a + span; }
    if (b > tSpan[1]) { b = tSpan[1]; a = b - span; }
    tv[0] = a; tv[1] = b; schedulePanels();
  }
  function hoverPanelAt(p, t, cx, cy) {
    var k = nearestByTime(L.t, t);
    setHover({ kind: "line", i: k }, cx, cy);
    var extra = [];
    p.spec.items.forEach(function (item) {
      if (item.kind === "hline") { return; }
      var s = seriesOf(item), j = nearestByTime(s.t, t);
      if (j >= 0 && Math.abs(s.t[j] - t) < 0.02 * (tv[1] - tv[0]) + 0.5) { extra.push(item.label + ": " + fmt(s.v[j], 3)); }
    });
    if (extra.length) { tip.textContent += "\n" + extra.join("\n"); }
  }
  function yRange(spec, i0s) {
    var vals = [];
    spec.items.forEach(function (item) {
      if (item.kind === "hline") { vals.push(item.value); return; }
      var s = seriesOf(item);
      var a = lowerBound(s.t, tv[0]), b = lowerBound(s.t, tv[1] + 1e-9);
      for (var j = a; j < b; j++) { var v = s.v[j]; if (v !== null && (!spec.log || v > 0)) { vals.push(v); } }
    });
    if (!vals.length) { return spec.log ? [0.1, 10] : [0, 1]; }
    vals.sort(function (x, y) { return x - y; });
    var lo = vals[0], hi = vals[vals.length - 1];
    if (spec.log) {
      lo = Math.pow(10, Math.floor(Math.log10(lo) * 4) / 4); hi = Math.pow(10, Math.ceil(Math.log10(hi) * 4) / 4);
      if (hi <= lo) { hi = lo * 10; }
      return [lo, hi];
    }
    var top = vals[Math.floor(0.995 * (vals.length - 1))];  // the PNG's rule: big spikes clip
    hi = top < 0.5 * hi ? Math.max(1.15 * top, 1.0) : hi * 1.05;
    if (!(hi > 0)) { hi = 1; }
    return [0, hi];
  }
  function drawPanel(p) {
    var s = sizeCanvas(p.canvas), ctx = s.ctx, spec = p.spec;
    var last = p === panels[panels.length - 1];
    var w = s.w - PAD.l - PAD.r, h = s.h - PAD.t - PAD.b - (last ? 12 : 0);
    ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, s.w, s.h);
    var yr = yRange(spec);
    var ly0 = spec.log ? Math.log10(yr[0]) : yr[0], ly1 = spec.log ? Math.log10(yr[1]) : yr[1];
    function X(t) { return PAD.l + (t - tv[0]) / (tv[1] - tv[0]) * w; }
    function Y(v) { var u = spec.log ? Math.log10(v) : v; return PAD.t + h - (u - ly0) / (ly1 - ly0) * h; }
    // outages
    ctx.fillStyle = "rgba(242,142,43,0.18)";
    D.outages.forEach(function (o) {
      if (o.t1 < tv[0] || o.t0 > tv[1]) { return; }
      var a = Math.max(X(o.t0), PAD.l), b = Math.min(X(o.t1), PAD.l + w);
      ctx.fillRect(a, PAD.t, Math.max(b - a, 1), h);
    });
    // axes and ticks
    ctx.strokeStyle = "#e5e5e5"; ctx.lineWidth = 1; ctx.fillStyle = "#444"; ctx.font = "10px sans-serif";
    ctx.beginPath();
    var tm0 = tv[0] / 60, tm1 = tv[1] / 60, st = niceStep(tm1 - tm0, Math.max(2, w / 90));
    ctx.textAlign = "center";
    for (var tm = Math.ceil(tm0 / st) * st; tm <= tm1 + 1e-9; tm += st) {
      var x = X(tm * 60); ctx.moveTo(x, PAD.t); ctx.lineTo(x, PAD.t + h);
      ctx.fillText(Number(tm.toFixed(6)).toString(), x, PAD.t + h + 12);
    }
    ctx.textAlign = "right";
    if (spec.log) {
      var mant = ly1 - ly0 > 2.5 ? [1] : [1, 2, 5];  // 1-2-5 ticks within a few decades
      for (var dec = Math.floor(ly0); dec <= Math.ceil(ly1); dec++) {
        mant.forEach(function (mm) {
          var v = mm * Math.pow(10, dec); if (v < yr[0] * 0.999 || v > yr[1] * 1.001) { return; }
          var yy = Y(v); ctx.moveTo(PAD.l, yy); ctx.lineTo(PAD.l + w, yy);
          ctx.fillText(v >= 1 ? v.toFixed(0) : Number(v.toPrecision(1)).toString(), PAD.l - 4, yy + 3);
        });
      }
    } else {
      var ys = niceStep(yr[1] - yr[0], Math.max(2, h / 28));
      for (var yv = Math.ceil(yr[0] / ys) * ys; yv <= yr[1] + 1e-9; yv += ys) {
        var y2 = Y(yv); ctx.moveTo(PAD.l, y2); ctx.lineTo(PAD.l + w, y2);
        ctx.fillText(Number(yv.toFixed(6)).toString(), PAD.l - 4, y2 + 3);
      }
    }
    ctx.stroke();
    ctx.strokeStyle = "#999"; ctx.strokeRect(PAD.l, PAD.t, w, h);
    ctx.save(); ctx.translate(11, PAD.t + h / 2); ctx.rotate(-Math.PI / 2); ctx.textAlign = "center";
    ctx.fillText(spec.ylabel, 0, 0); ctx.restore();
    ctx.textAlign = "left"; ctx.font = "11px sans-serif"; ctx.fillStyle = "#222";
    ctx.fillText(spec.title, PAD.l, 13);
    // data
    ctx.save(); ctx.beginPath(); ctx.rect(PAD.l, PAD.t, w, h); ctx.clip();
    var legend = [];
    spec.items.forEach(function (item) {
      ctx.setLineDash(item.dash || []);
      ctx.strokeStyle = item.color; ctx.fillStyle = item.color;
      if (item.kind === "hline") {
        ctx.lineWidth = 1; ctx.beginPath(); ctx.moveTo(PAD.l, Y(item.value)); ctx.lineTo(PAD.l + w, Y(item.value)); ctx.stroke();
        legend.push(item); return;
      }
      var sr = seriesOf(item);
      var a = Math.max(lowerBound(sr.t, tv[0]) - 1, 0), b = Math.min(lowerBound(sr.t, tv[1]) + 1, sr.t.length);
      var j, v;
      if (item.kind === "dots") {
        ctx.beginPath();
        for (j = a; j < b; j++) { v = sr.v[j]; if (v === null || (spec.log && v <= 0)) { continue; } ctx.rect(X(sr.t[j]) - 1, Y(v) - 1, 2, 2); }
        ctx.fill();
      } else {
        ctx.lineWidth = 1.2; ctx.beginPath();
        var pen = false;
        for (j = a; j < b; j++) {
          v = sr.v[j];
          if (v === null || (spec.log && v <= 0)) { pen = false; continue; }
          var xx = X(sr.t[j]), yy3 = Y(v);
          if (pen) { ctx.lineTo(xx, yy3); } else { ctx.moveTo(xx, yy3); pen = true; }
        }
        ctx.stroke();
      }
      legend.push(item);
    });
    ctx.setLineDash([]);
    if (cursorT !== null && cursorT >= tv[0] && cursorT <= tv[1]) {
      ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.beginPath(); ctx.moveTo(X(cursorT), PAD.t); ctx.lineTo(X(cursorT), PAD.t + h); ctx.stroke();
    }
    ctx.restore();
    if (spec.empty) { ctx.fillStyle = "#777"; ctx.textAlign = "center"; ctx.fillText(spec.empty, PAD.l + w / 2, PAD.t + h / 2); ctx.textAlign = "left"; }
    // legend (top right)
    ctx.font = "10px sans-serif";
    var lx = PAD.l + w - 6, ly = PAD.t + 12;
    ctx.textAlign = "right";
    legend.forEach(function (item) {
      var tw = ctx.measureText(item.label).width;
      ctx.fillStyle = "rgba(255,255,255,0.85)"; ctx.fillRect(lx - tw - 26, ly - 9, tw + 30, 13);
      ctx.fillStyle = "#222"; ctx.fillText(item.label, lx, ly);
      ctx.strokeStyle = item.color; ctx.fillStyle = item.color; ctx.lineWidth = 2; ctx.setLineDash(item.dash || []);
      if (item.kind === "dots") { ctx.fillRect(lx - tw - 14, ly - 5, 3, 3); }
      else { ctx.beginPath(); ctx.moveTo(lx - tw - 22, ly - 3); ctx.lineTo(lx - tw - 6, ly - 3); ctx.stroke(); }
      ctx.setLineDash([]);
      ly += 13;
    });
    ctx.textAlign = "left";
    if (last) {
      ctx.fillStyle = "#444"; ctx.font = "11px sans-serif"; ctx.textAlign = "center";
      ctx.fillText("minutes since " + D.start_utc, PAD.l + w / 2, s.h - 4);
      ctx.textAlign = "left";
    }
  }
  var panelsQueued = false;
  function schedulePanels() {
    if (panelsQueued) { return; }
    panelsQueued = true;
    requestAnimationFrame(function () { panelsQueued = false; panels.forEach(drawPanel); });
  }

  // ------------------------------------------------------------------ controls
  function buildControls() {
    var box = document.getElementById("controls");
    var sel = el("select", { id: "colour-by" });
    [["sigma", "sigma"], ["quality", "quality"], ["speed", "speed"]].forEach(function (o) {
      if (o[0] === "quality" && !D.has.quality) { return; }
      var opt = el("option", { value: o[0] }, o[1]);
      if (o[0] === colourBy) { opt.selected = true; }
      sel.appendChild(opt);
    });
    sel.addEventListener("change", function () { colourBy = sel.value; computeBins(); drawLegend(); scheduleMap(); });
    var lab = el("label", {}, "colour by ");
    lab.appendChild(sel); box.appendChild(lab);
    var c = D.counts;
    var items = [["fused", "fused track", null], ["fixes", "fixes (" + c.used + ")", "#a8a8a8"],
      ["downweighted", "down-weighted (" + c.downweighted + ")", "#e69500"],
      ["rejected", "rejected (" + c.rejected + ")", "#d62728"],
      ["outages", "outages (" + c.outages + ")", "#f28e2b"]];
    if (D.reference) { items.push(["reference", "reference", "#111111"]); }
    items.push(["basemap", "OpenStreetMap base map (online)", null]);
    items.forEach(function (it) {
      if (it[0] === "downweighted" && !D.has.weight) { return; }
      var l = el("label", {});
      var cb = el("input", { type: "checkbox", id: "layer-" + it[0] });
      cb.checked = layers[it[0]];
      cb.addEventListener("change", function () { layers[it[0]] = cb.checked; scheduleMap(); });
      l.appendChild(cb);
      if (it[2]) { var sw = el("span", { "class": "swatch" }); sw.style.background = it[2]; l.appendChild(sw); }
      l.appendChild(document.createTextNode(it[1]));
      box.appendChild(l);
    });
    var fit = el("button", { type: "button" }, "fit");
    fit.addEventListener("click", function () { fitView(); scheduleMap(); setTimeView(tSpan[0], tSpan[1]); });
    box.appendChild(fit);
  }
  function summary() {
    var c = D.counts, parts = [];
    parts.push(D.start_utc + ", " + (D.duration_s / 60).toFixed(1) + " min, " + (D.distance_m / 1000).toFixed(2) + " km");
    parts.push(c.epochs + " epochs (" + c.line_points + " drawn)");
    parts.push(c.fixes + " GNSS fixes: " + c.used + " used" + (D.has.weight ? ", " + c.downweighted + " down-weighted" : "") + ", " + c.rejected + " rejected");
    parts.push(c.outages + " outages");
    if (D.stats_text) { parts.push("error: " + D.stats_text); }
    document.getElementById("summary").textContent = parts.join(" \u00b7 ");
  }

  // ------------------------------------------------------------------ start
  var t0 = performance.now();
  var hash = {};
  location.hash.replace(/^#/, "").split("&").forEach(function (kv) {
    var p = kv.split("="); if (p[0]) { hash[p[0]] = decodeURIComponent(p[1] || ""); }
  });
  if (hash.basemap === "1") { layers.basemap = true; }
  summary(); buildControls(); buildPanels(); computeBins(); drawLegend();
  fitView();
  if (hash.zoom) { zoomMap(parseFloat(hash.zoom), view.w / 2, view.h / 2); }
  drawMap(); panels.forEach(drawPanel);
  var fullPoints = visiblePoints;
  window.addEventListener("resize", function () { scheduleMap(); schedulePanels(); });
  if (hash.probe !== undefined) {
    var k = Math.min(Math.max(parseInt(hash.probe, 10) || 0, 0), NL - 1);
    var mr = mapCanvas.getBoundingClientRect();
    setHover({ kind: "line", i: k }, mr.left + px(L.e[k]), mr.top + py(L.n[k]));
    var pr = document.getElementById("probe");
    pr.textContent = tooltipText({ kind: "line", i: k });
  }
  var ms = performance.now() - t0;
  statusEl.setAttribute("data-state", "done");
  statusEl.setAttribute("data-line-points", String(NL));
  statusEl.setAttribute("data-visible-points", String(fullPoints));
  statusEl.setAttribute("data-fixes", String(NF));
  statusEl.setAttribute("data-panels", panels.map(function (p) { return p.spec.id; }).join(","));
  statusEl.setAttribute("data-basemap", layers.basemap ? "on" : "off");
  statusEl.setAttribute("data-draw-ms", ms.toFixed(1));
  statusEl.textContent = "drawn " + fullPoints + " of " + NL + " track points, " + NF + " fixes, " +
    panels.length + " panels in " + ms.toFixed(0) + " ms";
})();
