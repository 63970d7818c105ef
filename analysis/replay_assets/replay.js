// dispatch replay: a canvas 2D renderer of one or two runs, written by hand (no library).
// The data are the JSON block #replay-data (typed arrays in base64, see analysis/replay.py).
// Text from the input files is put on the page with textContent only, never as markup.
(function () {
  "use strict";

  var TYPES = { float32: Float32Array, float64: Float64Array, int32: Int32Array, uint8: Uint8Array };
  function decode(o) {
    if (o === null || typeof o !== "object") return o;
    if (Array.isArray(o)) return o.map(decode);
    if (typeof o.t === "string" && typeof o.b === "string" && TYPES[o.t]) {
      var bin = atob(o.b), n = bin.length, u = new Uint8Array(n);
      for (var i = 0; i < n; i++) u[i] = bin.charCodeAt(i);
      return new TYPES[o.t](u.buffer);
    }
    var out = {};
    for (var k in o) if (Object.prototype.hasOwnProperty.call(o, k)) out[k] = decode(o[k]);
    return out;
  }
  var RAW = JSON.parse(document.getElementById("replay-data").textContent);
  var DATA = decode(RAW);

  // ---------------------------------------------------------------- helpers
  function el(tag, attrs, text) {
    var e = document.createElement(tag);
    if (attrs) for (var k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined && text !== null) e.textContent = String(text);
    return e;
  }
  function ub(a, x) { // number of elements <= x in the sorted array a
    var lo = 0, hi = a.length;
    while (lo < hi) { var m = (lo + hi) >> 1; if (a[m] <= x) lo = m + 1; else hi = m; }
    return lo;
  }
  function ubRange(a, lo, hi, x) { // last index i in [lo, hi) with a[i] <= x, or lo - 1
    var l = lo, h = hi;
    while (l < h) { var m = (l + h) >> 1; if (a[m] <= x) l = m + 1; else h = m; }
    return l - 1;
  }
  function clock(t) {
    var s = Math.max(0, Math.floor(t)), h = Math.floor(s / 3600), m = Math.floor(s / 60) % 60;
    var d = h >= 24 ? Math.floor(h / 24) + "d " : "";
    return d + (h % 24) + ":" + (m < 10 ? "0" : "") + m + ":" + (s % 60 < 10 ? "0" : "") + (s % 60);
  }
  function sorted(arr) { var a = Float64Array.from(arr); a.sort(); return a; }
  function fin(x) { return x === x ? x : Infinity; } // NaN (not yet / never) -> +inf

  var COLORS = {
    idle: "#9aa0a6", to_pickup: "#f5a623", occupied: "#2e86de", occupied_2: "#1b4f9c",
    "occupied_3+": "#7b1fa2", repositioning: "#26a69a", failed: "#d32f2f",
    to_charger: "#9ccc65", queueing: "#c0ca33", charging: "#2e7d32",
    on_break: "#8d6e63", to_depot: "#546e7a", off_shift: "#b0b7bf"
  };
  // marks of the demand-responsive features (prebooking, offers, meeting points)
  var MARKS = { booked: "#d81b60", declined: "#ffb300", walk: "#5d4037", refused: "#d32f2f" };
  var ROAD_LABELS = {
    idle: "idle", to_pickup: "to pickup", occupied: "carrying 1 rider (or dropping off)",
    occupied_2: "carrying 2 riders", "occupied_3+": "carrying 3+ riders",
    repositioning: "repositioning", failed: "broken down", to_charger: "to a charger",
    queueing: "at a charger, queueing", charging: "at a charger, charging",
    on_break: "driver on a break", to_depot: "driving to its depot (shift over)", off_shift: "off shift (not in the fleet)"
  };
  var VOXEL_LABELS = {
    idle: "idle", to_pickup: "to its task", occupied: "at its task (serving)",
    occupied_2: "2 tasks", "occupied_3+": "3+ tasks", repositioning: "repositioning",
    failed: "broken down", to_charger: "to a charger", queueing: "queueing", charging: "charging",
    on_break: "on a break", to_depot: "to its depot (shift over)", off_shift: "off shift"
  };

  // ---------------------------------------------------------------- one run
  function Run(d, index) {
    this.d = d; this.index = index;
    var V = d.vehicles, n = V.id.length;
    this.n = n;
    this.voxel = d.space === "voxel";
    this.labels = this.voxel ? VOXEL_LABELS : ROAD_LABELS;
    // headings per keyframe: toward the next position, else the last known one
    var kx = V.kfX, ky = V.kfY, off = V.kfOff, head = new Float32Array(kx.length);
    for (var v = 0; v < n; v++) {
      var last = 0;
      for (var k = off[v]; k < off[v + 1]; k++) {
        if (k + 1 < off[v + 1] && (kx[k + 1] !== kx[k] || ky[k + 1] !== ky[k]))
          last = Math.atan2(ky[k + 1] - ky[k], kx[k + 1] - kx[k]);
        head[k] = last;
      }
    }
    this.head = head;
    this.px = new Float32Array(n); this.py = new Float32Array(n); this.pz = new Float32Array(n);
    this.ph = new Float32Array(n); this.state = new Uint8Array(n); this.onb = new Uint8Array(n);
    this.byId = {};
    for (var i = 0; i < n; i++) this.byId[V.id[i]] = i;
    this.stateIndex = {};
    d.fleetStates.forEach(function (s, i) { this.stateIndex[s] = i; }, this);
    this.offShift = d.fleetStates.indexOf("off_shift");
    this.prepareTasks();
    this.prepareSeries();
  }

  Run.prototype.prepareTasks = function () {
    var T = this.d.tasks;
    this.m = T ? T.rel.length : 0;
    this.tasksOf = {};
    if (!T) { this.kpi = null; return; }
    var m = this.m, refused = {}, F = T.features || {};
    this.d.refused.forEach(function (s) { refused[this.d.taskStates.indexOf(s)] = true; }, this);
    var declined = this.d.taskStates.indexOf("declined"), cut = this.d.taskStates.indexOf(this.d.cutOff);
    var wS = [], wE = [], oS = [], oE = [], dS = [], rS = [], xS = [], cS = [], bS = [], bE = [],
        kS = [], kE = [], span = 0, open = [], booked = [], walkMax = 0;
    for (var i = 0; i < m; i++) {
      var r = T.rel[i], p = fin(T.pick[i]), c = fin(T.close[i]);
      wS.push(r); wE.push(Math.max(r, Math.min(p, c)));
      if (p !== Infinity) { oS.push(p); oE.push(Math.max(p, c)); }
      if (T.done[i] === T.done[i]) dS.push(T.done[i]);
      if (refused[T.state[i]] && c !== Infinity) rS.push(c);
      if (T.state[i] === declined && c !== Infinity) xS.push(c);
      if (T.state[i] === cut && c !== Infinity) cS.push(c);
      if (F.booked && T.bk[i] === T.bk[i]) {
        bS.push(T.bk[i]); bE.push(Math.max(T.bk[i], Math.min(p, c)));
        if (T.bk[i] < r) booked.push(i);
      }
      if (F.walks) {
        var w = this.walk(i);
        if (w[1] > w[0]) { kS.push(w[0]); kE.push(w[1]); }
        if (w[3] > w[2]) { kS.push(w[2]); kE.push(w[3]); walkMax = Math.max(walkMax, w[3] - w[2]); }
      }
      if (c === Infinity) open.push(i); else span = Math.max(span, c - r);
    }
    this.kpi = { wS: sorted(wS), wE: sorted(wE), oS: sorted(oS), oE: sorted(oE), dS: sorted(dS),
                 rS: sorted(rS), xS: sorted(xS), cS: sorted(cS), bS: sorted(bS), bE: sorted(bE),
                 kS: sorted(kS), kE: sorted(kE) };
    booked.sort(function (a, b) { return T.bk[a] - T.bk[b]; });
    this.bookedTasks = booked; this.bookedBk = Float64Array.from(booked.map(function (i) { return T.bk[i]; }));
    this.span = span; this.openTasks = open; this.walkMax = walkMax;
    // each vehicle's tasks (their final vehicle)
    for (var j = 0; j < m; j++) {
      var a = T.agent[j];
      if (a >= 0) (this.tasksOf[a] = this.tasksOf[a] || []).push(j);
    }
  };

  // a rider's walks: [to the boarding point from, until, from the alighting point from, until]
  // (walk_to_board_m / walk_from_alight_m at the scenario's walking speed; see analysis/replay.py)
  Run.prototype.walk = function (i) {
    var T = this.d.tasks, v = T.walkSpeed, r = T.rel[i], out = [0, 0, 0, 0];
    if (T.wTo[i] > 0) { out[0] = r; out[1] = Math.min(r + T.wTo[i] / v, fin(T.pick[i]), fin(T.close[i])); }
    if (T.wFrom[i] > 0 && T.done[i] === T.done[i]) { out[2] = T.done[i]; out[3] = T.done[i] + T.wFrom[i] / v; }
    return out;
  };

  Run.prototype.counts = function (t) {
    var K = this.kpi;
    if (!K) return { waiting: 0, onboard: 0, delivered: 0, rejected: 0, declined: 0, cutoff: 0, booked: 0, walking: 0 };
    return { waiting: ub(K.wS, t) - ub(K.wE, t), onboard: ub(K.oS, t) - ub(K.oE, t),
             delivered: ub(K.dS, t), rejected: ub(K.rS, t), declined: ub(K.xS, t),
             cutoff: ub(K.cS, t), booked: ub(K.bS, t) - ub(K.bE, t),
             walking: ub(K.kS, t) - ub(K.kE, t) };
  };

  Run.prototype.stateAt = function (v, t) {
    var V = this.d.vehicles, i = ubRange(V.stT, V.stOff[v], V.stOff[v + 1], t);
    if (i < V.stOff[v]) i = V.stOff[v];
    return i < V.stOff[v + 1] ? i : -1;
  };

  // every vehicle's position, heading, state and riders at t
  Run.prototype.update = function (t) {
    var V = this.d.vehicles, off = V.kfOff, kt = V.kfT, kx = V.kfX, ky = V.kfY, kz = V.kfZ;
    for (var v = 0; v < this.n; v++) {
      var lo = off[v], hi = off[v + 1];
      if (hi <= lo) continue;
      var k = ubRange(kt, lo, hi, t);
      if (k < lo) { this.px[v] = kx[lo]; this.py[v] = ky[lo]; this.pz[v] = kz[lo]; this.ph[v] = this.head[lo]; }
      else if (k >= hi - 1) { this.px[v] = kx[hi - 1]; this.py[v] = ky[hi - 1]; this.pz[v] = kz[hi - 1]; this.ph[v] = this.head[hi - 1]; }
      else {
        var dt = kt[k + 1] - kt[k], a = dt > 0 ? (t - kt[k]) / dt : 1;
        this.px[v] = kx[k] + a * (kx[k + 1] - kx[k]);
        this.py[v] = ky[k] + a * (ky[k + 1] - ky[k]);
        this.pz[v] = kz[k] + a * (kz[k + 1] - kz[k]);
        this.ph[v] = this.head[k];
      }
      var s = this.stateAt(v, t);
      this.state[v] = s >= 0 ? V.stCode[s] : 0;
      this.onb[v] = s >= 0 ? V.stOn[s] : 0;
    }
  };

  Run.prototype.socAt = function (t) {
    var S = this.d.soc;
    if (!S || !S.t.length) return null;
    var i = Math.max(0, ub(S.t, t) - 1);
    return { i: i, p10: S.p10[i], p50: S.p50[i], p90: S.p90[i] };
  };

  // time series over the run for the panel's small chart
  Run.prototype.prepareSeries = function () {
    var N = 200, t0 = this.d.t0, t1 = this.d.t1, V = this.d.vehicles;
    var ts = new Float64Array(N), wait = new Float32Array(N), onb = new Float32Array(N),
        busy = new Float32Array(N);
    var idle = this.stateIndex.idle, off = this.offShift;
    for (var i = 0; i < N; i++) {
      var t = t0 + (t1 - t0) * i / (N - 1), c = this.counts(t), b = 0;
      ts[i] = t; wait[i] = c.waiting; onb[i] = c.onboard;
      for (var v = 0; v < this.n; v++) {
        var s = this.stateAt(v, t);
        if (s >= 0 && V.stCode[s] !== idle && V.stCode[s] !== off) b++;
      }
      busy[i] = b;
    }
    this.series = { t: ts, lines: [
      { name: "waiting", color: "#ff7043", y: wait },
      { name: "on board", color: "#2e86de", y: onb },
      { name: "vehicles busy (not idle, not off shift)", color: "#777", y: busy }] };
  };

  // ---------------------------------------------------------------- one view (map + panel)
  function View(run, root) {
    this.run = run; this.scale = 1; this.ox = 0; this.oy = 0; this.follow = -1;
    this.bgKey = ""; this.fitted = false;
    var d = run.d, sec = el("section", { "class": "view", "data-run": String(run.index) });
    var wrap = el("div", { "class": "mapwrap" });
    this.canvas = el("canvas", { "class": "map" });
    wrap.appendChild(this.canvas);
    var title = el("h2", { "class": "title" },
                   (d.scenario || "run") + " \u00b7 " + d.runId);
    wrap.appendChild(title);
    sec.appendChild(wrap);
    var p = el("aside", { "class": "panel" });
    p.appendChild(el("h3", null, "requests"));
    var k = el("div", { "class": "kpis" });
    this.kpiEls = {};
    var F = (d.tasks && d.tasks.features) || {};
    [["waiting", "waiting"], ["onboard", "on board"], ["delivered", "delivered"],
     ["rejected", "rejected / expired"], ["declined", "declined the offer", F.offers],
     ["cutoff", "cut off by the run's end"], ["booked", "booked ahead, not yet picked up", F.booked],
     ["walking", "walking", F.walks]].forEach(function (x) {
      if (x.length > 2 && !x[2]) return;
      var box = el("div", { "class": "kpi" }, x[1]);
      var b = el("b", { "data-kpi": x[0] }, "0");
      box.insertBefore(b, box.firstChild);
      k.appendChild(box); this.kpiEls[x[0]] = b;
    }, this);
    p.appendChild(k);
    this.served = el("div", { "class": "muted", "data-kpi-extra": "served" });
    p.appendChild(this.served);
    p.appendChild(el("h3", null, "vehicles by state"));
    this.stateTable = el("table");
    this.stateCells = [];
    d.fleetStates.forEach(function (s, i) {
      var tr = el("tr"), td = el("td");
      var sw = el("span", { "class": "sw" }); sw.style.background = COLORS[s] || "#000";
      td.appendChild(sw); td.appendChild(document.createTextNode(run.labels[s] || s));
      var n = el("td", { "class": "n", "data-state": s }, "0");
      tr.appendChild(td); tr.appendChild(n); this.stateTable.appendChild(tr);
      this.stateCells.push([tr, n]);
    }, this);
    p.appendChild(this.stateTable);
    this.occ = el("div", { "class": "muted", "data-kpi-extra": "occupancy" });
    p.appendChild(this.occ);
    if (d.soc) {
      var sp = el("div", { "class": "soc", "data-panel": "soc" });
      sp.appendChild(el("h3", null, "state of charge"));
      this.socText = el("div", { "data-kpi-extra": "soc" });
      sp.appendChild(this.socText);
      p.appendChild(sp);
    }
    p.appendChild(el("h3", null, "over the run"));
    this.chart = el("canvas", { "class": "series" });
    p.appendChild(this.chart);
    var lg = el("div", { "class": "muted" });
    run.series.lines.forEach(function (l) {
      var sw = el("span", { "class": "sw" }); sw.style.background = l.color;
      lg.appendChild(sw); lg.appendChild(document.createTextNode(l.name + "  "));
    });
    p.appendChild(lg);
    this.followBox = el("div", { "class": "follow", "data-panel": "follow" });
    p.appendChild(el("h3", null, "followed vehicle"));
    this.followBox.appendChild(el("div", { "class": "none" }, "click a vehicle or search its id"));
    p.appendChild(this.followBox);
    if (d.stations) {
      p.appendChild(el("h3", null, "charging stations"));
      var ul = el("ul", { "data-panel": "stations" });
      d.stations.id.forEach(function (s, i) {
        ul.appendChild(el("li", null, s + " (" + d.stations.plugs[i] + " plugs)"));
      });
      p.appendChild(ul);
    }
    var info = el("div", { "class": "muted" });
    var parts = [];
    for (var key in d.info) if (d.info[key] !== null) parts.push(key + " " + d.info[key]);
    info.textContent = parts.join(" \u00b7 ") + " \u00b7 written by " + (d.writer || "?");
    p.appendChild(info);
    sec.appendChild(p);
    root.appendChild(sec);
    this.section = sec;
    this.bindMouse();
  }

  View.prototype.fit = function () {
    var b = this.run.d.bounds, w = this.cw, h = this.ch, pad = 16, top = 34; // below the title
    var sx = (w - 2 * pad) / Math.max(b[2] - b[0], 1e-9), sy = (h - pad - top) / Math.max(b[3] - b[1], 1e-9);
    this.scale = Math.max(1e-6, Math.min(sx, sy));
    this.ox = (w - (b[2] - b[0]) * this.scale) / 2 - b[0] * this.scale;
    this.oy = top + (h - pad - top + (b[3] - b[1]) * this.scale) / 2 + b[1] * this.scale;
    this.fitted = true;
  };
  View.prototype.sx = function (x) { return this.ox + x * this.scale; };
  View.prototype.sy = function (y) { return this.oy - y * this.scale; };

  View.prototype.resize = function () {
    var r = this.canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    var w = Math.max(1, Math.round(r.width)), h = Math.max(1, Math.round(r.height));
    if (w !== this.cw || h !== this.ch) {
      this.cw = w; this.ch = h; this.dpr = dpr;
      this.canvas.width = Math.round(w * dpr); this.canvas.height = Math.round(h * dpr);
      if (!this.fitted) this.fit();
      this.bgKey = "";
    }
    var cr = this.chart.getBoundingClientRect();
    if (cr.width && (this.chart.width !== Math.round(cr.width * dpr))) {
      this.chart.width = Math.round(cr.width * dpr); this.chart.height = Math.round(cr.height * dpr);
      this.chartBg = null;
    }
  };

  View.prototype.bindMouse = function () {
    var self = this, c = this.canvas, drag = null;
    c.addEventListener("mousedown", function (e) { drag = { x: e.clientX, y: e.clientY, moved: false }; });
    window.addEventListener("mousemove", function (e) {
      if (!drag) return;
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
      if (drag.moved) {
        self.ox += dx; self.oy += dy; drag.x = e.clientX; drag.y = e.clientY;
        self.centre = false; self.bgKey = ""; APP.dirty = true;
      }
    });
    window.addEventListener("mouseup", function (e) {
      if (drag && !drag.moved && e.target === c) self.pick(e);
      drag = null;
    });
    c.addEventListener("wheel", function (e) {
      e.preventDefault();
      var r = c.getBoundingClientRect(), mx = e.clientX - r.left, my = e.clientY - r.top;
      var f = Math.exp(-e.deltaY * 0.0015);
      self.ox = mx - (mx - self.ox) * f; self.oy = my - (my - self.oy) * f; self.scale *= f;
      self.bgKey = ""; APP.dirty = true;
    }, { passive: false });
  };

  View.prototype.pick = function (e) {
    var r = this.canvas.getBoundingClientRect(), mx = e.clientX - r.left, my = e.clientY - r.top;
    var best = -1, bd = 14 * 14, run = this.run;
    for (var v = 0; v < run.n; v++) {
      if (run.state[v] === run.offShift && !LAYERS.offshift) continue;
      var dx = this.sx(run.px[v]) - mx, dy = this.sy(run.py[v]) - my, dd = dx * dx + dy * dy;
      if (dd < bd) { bd = dd; best = v; }
    }
    this.setFollow(best);
  };

  View.prototype.setFollow = function (v) {
    this.follow = v; this.centre = v >= 0; this.followKey = ""; APP.dirty = true;
  };

  // the static layer: streets or obstacles, stations
  View.prototype.background = function () {
    var key = [this.cw, this.ch, this.scale, this.ox, this.oy, LAYERS.network, LAYERS.stations].join(",");
    if (key === this.bgKey) return;
    this.bgKey = key;
    if (!this.bg) this.bg = document.createElement("canvas");
    var bg = this.bg, dpr = this.dpr, d = this.run.d;
    bg.width = this.canvas.width; bg.height = this.canvas.height;
    var g = bg.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.fillStyle = "#fff"; g.fillRect(0, 0, this.cw, this.ch);
    if (d.net && LAYERS.network) {
      var x = d.net.x, y = d.net.y, e = d.net.e;
      g.strokeStyle = "#d4d7dc"; g.lineWidth = 1; g.beginPath();
      for (var i = 0; i < e.length; i += 2) {
        g.moveTo(this.sx(x[e[i]]), this.sy(y[e[i]]));
        g.lineTo(this.sx(x[e[i + 1]]), this.sy(y[e[i + 1]]));
      }
      g.stroke();
    }
    if (this.run.voxel) {
      var b = d.bounds;
      g.strokeStyle = "#bbb"; g.strokeRect(this.sx(b[0]), this.sy(b[3]), (b[2] - b[0]) * this.scale, (b[3] - b[1]) * this.scale);
      var O = d.obstacles;
      if (O && LAYERS.network) {
        var zt = d.worldZ || 1;
        for (var j = 0; j < O.x0.length; j++) {
          var shade = Math.round(200 - 150 * Math.min(1, O.z1[j] / zt));
          g.fillStyle = "rgb(" + shade + "," + shade + "," + (shade + 10) + ")";
          g.fillRect(this.sx(O.x0[j]), this.sy(O.y1[j]), (O.x1[j] - O.x0[j]) * this.scale, (O.y1[j] - O.y0[j]) * this.scale);
        }
      }
    }
    if (d.stations && LAYERS.stations) {
      g.fillStyle = "#2e7d32";
      for (var s = 0; s < d.stations.x.length; s++)
        g.fillRect(this.sx(d.stations.x[s]) - 4, this.sy(d.stations.y[s]) - 4, 8, 8);
    }
    if (d.transit && LAYERS.transit) { // the stations the riders' legs name: white rings
      g.fillStyle = "#fff"; g.strokeStyle = TRANSIT.station; g.lineWidth = 1.5;
      for (var q = 0; q < d.transit.sx.length; q++) {
        g.beginPath(); g.arc(this.sx(d.transit.sx[q]), this.sy(d.transit.sy[q]), 3.5, 0, 2 * Math.PI);
        g.fill(); g.stroke();
      }
    }
  };

  View.prototype.draw = function (t) {
    var run = this.run, d = run.d, V = d.vehicles, T = d.tasks;
    run.update(t);
    if (this.centre && this.follow >= 0) {
      this.ox = this.cw / 2 - run.px[this.follow] * this.scale;
      this.oy = this.ch / 2 + run.py[this.follow] * this.scale;
    }
    this.background();
    var c = this.canvas.getContext("2d"), dpr = this.dpr;
    c.setTransform(1, 0, 0, 1, 0, 0);
    c.drawImage(this.bg, 0, 0);
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    var self = this;
    // trails (the path driven over the last while; in the voxel world from the start)
    if (LAYERS.trails || this.follow >= 0) {
      var win = run.voxel ? Infinity : Math.max(300, 60 * Math.abs(APP.speed));
      c.lineWidth = 1.2;
      for (var v = 0; v < run.n; v++) {
        if (!LAYERS.trails && v !== this.follow) continue;
        var lo = V.kfOff[v], hi = V.kfOff[v + 1], k = ubRange(V.kfT, lo, hi, t);
        if (k < lo) continue;
        var k0 = win === Infinity ? lo : Math.max(lo, ubRange(V.kfT, lo, hi, t - win));
        c.strokeStyle = v === this.follow ? "rgba(0,0,0,.7)" : "rgba(90,90,90,.35)";
        c.beginPath(); c.moveTo(this.sx(V.kfX[k0]), this.sy(V.kfY[k0]));
        for (var j = k0 + 1; j <= k; j++) c.lineTo(this.sx(V.kfX[j]), this.sy(V.kfY[j]));
        c.lineTo(this.sx(run.px[v]), this.sy(run.py[v]));
        c.stroke();
      }
    }
    // requests
    if (T && (LAYERS.requests || LAYERS.arcs || LAYERS.flashes || LAYERS.walks)) {
      var flash = Math.max(20, 1.5 * Math.abs(APP.speed));
      var first = ub(T.rel, t - run.span - flash - run.walkMax), last = ub(T.rel, t);
      var refused = {}, airKind = T.kind.indexOf("air"), F = T.features || {};
      var declined = d.taskStates.indexOf("declined");
      d.refused.forEach(function (s) { refused[d.taskStates.indexOf(s)] = true; });
      var dotted = function (x0, y0, x1, y1) {
        c.strokeStyle = MARKS.walk; c.lineWidth = 1.5; c.setLineDash([2, 3]);
        c.beginPath(); c.moveTo(x0, y0); c.lineTo(x1, y1); c.stroke(); c.setLineDash([]);
      };
      var drawTask = function (i) {
        var p = fin(T.pick[i]), cl = fin(T.close[i]);
        var bk = F.booked ? T.bk[i] : NaN, isBooked = bk === bk && bk <= t;
        if (T.rel[i] > t && !isBooked) return;
        var x = self.sx(T.x[i]), y = self.sy(T.y[i]);
        var walks = F.walks && T.bx[i] === T.bx[i], w = F.walks ? run.walk(i) : null;
        if (t < p && t < cl) {
          // a rider walking to the boarding point is drawn on the way, then waits there
          if (walks && T.wTo[i] > 0 && T.rel[i] <= t) {
            var bx = self.sx(T.bx[i]), by = self.sy(T.by[i]);
            if (LAYERS.walks) dotted(x, y, bx, by);
            var f = Math.min(1, (t - T.rel[i]) / (T.wTo[i] / T.walkSpeed));
            x += f * (bx - x); y += f * (by - y);
          }
          if (LAYERS.requests) {
            var taken = T.asg[i] <= t, air = airKind >= 0 && T.kindCode[i] === airKind;
            c.lineWidth = 1.5;
            if (isBooked) {
              // booked ahead: a diamond from booking to pickup (hollow: a vehicle's plan holds it)
              c.fillStyle = c.strokeStyle = MARKS.booked;
              c.beginPath(); c.moveTo(x, y - 4); c.lineTo(x + 4, y); c.lineTo(x, y + 4); c.lineTo(x - 4, y); c.closePath();
              if (taken) c.stroke(); else c.fill();
            } else {
              // filled: nobody is coming yet; hollow: a vehicle is on its way; circles: air tasks
              c.fillStyle = c.strokeStyle = "#ff7043";
              if (air) { c.beginPath(); c.arc(x, y, 3, 0, 2 * Math.PI); if (taken) c.stroke(); else c.fill(); }
              else if (taken) c.strokeRect(x - 2.5, y - 2.5, 5, 5);
              else c.fillRect(x - 2.5, y - 2.5, 5, 5);
            }
          }
        } else if (p <= t && t < cl) {
          if (LAYERS.arcs && T.dx[i] === T.dx[i]) {
            if (walks && T.ax[i] === T.ax[i]) { x = self.sx(T.bx[i]); y = self.sy(T.by[i]); }
            var X = self.sx(walks && T.ax[i] === T.ax[i] ? T.ax[i] : T.dx[i]),
                Y = self.sy(walks && T.ay[i] === T.ay[i] ? T.ay[i] : T.dy[i]), mx = (x + X) / 2, my = (y + Y) / 2;
            var nx = -(Y - y) * 0.2, ny = (X - x) * 0.2;
            c.strokeStyle = "rgba(46,134,222,.35)"; c.lineWidth = 1;
            c.beginPath(); c.moveTo(x, y); c.quadraticCurveTo(mx + nx, my + ny, X, Y); c.stroke();
          } else if (LAYERS.requests && run.voxel) {
            c.strokeStyle = "#2e86de"; c.strokeRect(x - 3, y - 3, 6, 6);
          }
        } else if (cl <= t && t - cl < flash && LAYERS.flashes &&
                   (refused[T.state[i]] || T.state[i] === declined)) {
          var a = 1 - (t - cl) / flash, rgb = T.state[i] === declined ? "255,179,0" : "211,47,47";
          c.strokeStyle = "rgba(" + rgb + "," + a.toFixed(3) + ")"; c.lineWidth = 2;
          c.beginPath(); c.arc(x, y, 4 + 10 * (1 - a), 0, 2 * Math.PI); c.stroke();
        }
        // a rider walking from the alighting point to the destination after the drop-off
        if (walks && LAYERS.walks && w[3] > w[2] && w[2] <= t && t < w[3] && T.ax[i] === T.ax[i]) {
          var ax = self.sx(T.ax[i]), ay = self.sy(T.ay[i]), ex = self.sx(T.dx[i]), ey = self.sy(T.dy[i]);
          dotted(ax, ay, ex, ey);
          var g2 = (t - w[2]) / (w[3] - w[2]);
          c.fillStyle = MARKS.walk; c.beginPath();
          c.arc(ax + g2 * (ex - ax), ay + g2 * (ey - ay), 2.5, 0, 2 * Math.PI); c.fill();
        }
      };
      for (var i = first; i < last; i++) drawTask(i);
      for (var o = 0; o < run.openTasks.length; o++) if (run.openTasks[o] < first) drawTask(run.openTasks[o]);
      // booked ahead, not yet at their requested departure
      for (var q = 0, nb = ub(run.bookedBk, t); q < nb; q++)
        if (T.rel[run.bookedTasks[q]] > t) drawTask(run.bookedTasks[q]);
    }
    // riders off the fleet: on a train or on foot, a dot moving straight from stop to stop
    if (d.transit && LAYERS.transit) {
      var R = d.transit, r0 = ub(R.t0, t - R.span - 1), r1 = ub(R.t0, t);
      for (var q2 = r0; q2 < r1; q2++) {
        if (R.t1[q2] <= t) continue;
        var fr = R.t1[q2] > R.t0[q2] ? (t - R.t0[q2]) / (R.t1[q2] - R.t0[q2]) : 1;
        c.fillStyle = R.mode[q2] === 1 ? TRANSIT.train : TRANSIT.walk;
        c.beginPath();
        c.arc(this.sx(R.x0[q2] + fr * (R.x1[q2] - R.x0[q2])), this.sy(R.y0[q2] + fr * (R.y1[q2] - R.y0[q2])),
              R.mode[q2] === 1 ? 3 : 2, 0, 2 * Math.PI);
        c.fill();
      }
    }
    // vehicles: one path per state, a triangle along the heading (drones: a diamond)
    var kinds = V.kindNames, uav = kinds.indexOf("uav");
    var nStates = d.fleetStates.length;
    // off shift: not in the fleet, not drawn (a layer shows them as rings where they wait)
    if (run.offShift >= 0 && LAYERS.offshift) {
      c.strokeStyle = COLORS.off_shift; c.lineWidth = 1.5; c.beginPath();
      for (var u = 0; u < run.n; u++) {
        if (run.state[u] !== run.offShift) continue;
        var ux = this.sx(run.px[u]), uy = this.sy(run.py[u]);
        c.moveTo(ux + 4, uy); c.arc(ux, uy, 4, 0, 2 * Math.PI);
      }
      c.stroke();
    }
    for (var s = 0; s < nStates; s++) {
      if (s === run.offShift) continue;
      c.fillStyle = COLORS[d.fleetStates[s]] || "#000";
      c.beginPath();
      for (var w = 0; w < run.n; w++) {
        if (run.state[w] !== s) continue;
        var X0 = this.sx(run.px[w]), Y0 = this.sy(run.py[w]);
        if (V.kind[w] === uav) {
          var r = 4.5;
          c.moveTo(X0, Y0 - r); c.lineTo(X0 + r, Y0); c.lineTo(X0, Y0 + r); c.lineTo(X0 - r, Y0); c.closePath();
        } else {
          var h = run.ph[w], ch = Math.cos(h), sh = -Math.sin(h), L = 6, W = 3.5;
          c.moveTo(X0 + ch * L, Y0 + sh * L);
          c.lineTo(X0 - ch * L * 0.6 - sh * W, Y0 - sh * L * 0.6 + ch * W);
          c.lineTo(X0 - ch * L * 0.6 + sh * W, Y0 - sh * L * 0.6 - ch * W);
          c.closePath();
        }
      }
      c.fill();
    }
    if (this.follow >= 0) {
      var f = this.follow;
      c.strokeStyle = "#000"; c.lineWidth = 2; c.beginPath();
      c.arc(this.sx(run.px[f]), this.sy(run.py[f]), 10, 0, 2 * Math.PI); c.stroke();
    }
    this.panel(t);
  };

  View.prototype.panel = function (t) {
    var run = this.run, d = run.d, cts = run.counts(t);
    for (var k in this.kpiEls) {
      var s = String(cts[k]);
      if (this.kpiEls[k].textContent !== s) this.kpiEls[k].textContent = s;
    }
    var closed = cts.delivered + cts.rejected + cts.declined;
    this.served.textContent = "served so far: " + (closed ? (100 * cts.delivered / closed).toFixed(1) + " %" : "\u2013") +
      " of " + closed + " closed requests";
    var byState = new Array(d.fleetStates.length).fill(0), riders = 0, seats = 0, inUse = 0;
    for (var v = 0; v < run.n; v++) {
      byState[run.state[v]]++; riders += run.onb[v];
      if (run.state[v] !== run.offShift) seats += d.vehicles.cap[v];
      if (run.onb[v] > 0) inUse++;
    }
    this.stateCells.forEach(function (x, i) {
      x[1].textContent = String(byState[i]);
      x[0].style.display = byState[i] || d.fleetStates[i] === "idle" || i < 3 ? "" : "none";
    });
    // robots serve tasks, not riders: no seats to fill
    this.occ.textContent = run.voxel ? "vehicles at a task: " + inUse + " of " + run.n :
      "riders on board " + riders + " in " + inUse + " vehicles; seats taken " +
      (seats ? (100 * riders / seats).toFixed(1) : "0") + " %";
    if (this.socText) {
      var q = run.socAt(t);
      this.socText.textContent = q ? "median " + (100 * q.p50).toFixed(0) + " %, 10\u201390 %: " +
        (100 * q.p10).toFixed(0) + "\u2013" + (100 * q.p90).toFixed(0) + " %" : "no samples";
    }
    this.drawChart(t);
    this.followPanel(t);
  };

  View.prototype.drawChart = function (t) {
    var cv = this.chart, g = cv.getContext("2d"), W = cv.width, H = cv.height, S = this.run.series;
    if (!W || !H) return;
    if (!this.chartBg) {
      var bg = document.createElement("canvas"); bg.width = W; bg.height = H;
      var b = bg.getContext("2d"), max = 1;
      S.lines.forEach(function (l) { for (var i = 0; i < l.y.length; i++) max = Math.max(max, l.y[i]); });
      b.fillStyle = "#fff"; b.fillRect(0, 0, W, H);
      var t0 = S.t[0], t1 = S.t[S.t.length - 1] || 1;
      S.lines.forEach(function (l) {
        b.strokeStyle = l.color; b.lineWidth = 1.5; b.beginPath();
        for (var i = 0; i < l.y.length; i++) {
          var x = (S.t[i] - t0) / (t1 - t0 || 1) * (W - 2) + 1, y = H - 2 - l.y[i] / max * (H - 6);
          if (i) b.lineTo(x, y); else b.moveTo(x, y);
        }
        b.stroke();
      });
      this.chartBg = bg; this.chartSpan = [t0, t1];
    }
    g.drawImage(this.chartBg, 0, 0);
    var sp = this.chartSpan, cx = (t - sp[0]) / (sp[1] - sp[0] || 1) * (W - 2) + 1;
    g.strokeStyle = "#000"; g.lineWidth = 1; g.beginPath(); g.moveTo(cx, 0); g.lineTo(cx, H); g.stroke();
  };

  View.prototype.followPanel = function (t) {
    var run = this.run, d = run.d, v = this.follow, box = this.followBox, T = d.tasks;
    var key = v + ":" + (v >= 0 ? run.state[v] + ":" + Math.floor(t) : "");
    if (key === this.followKey) return;
    this.followKey = key;
    while (box.firstChild) box.removeChild(box.firstChild);
    if (v < 0) { box.appendChild(el("div", { "class": "none" }, "click a vehicle or search its id")); return; }
    var id = d.vehicles.id[v], kind = d.vehicles.kindNames[d.vehicles.kind[v]];
    box.appendChild(el("div", { "data-vehicle": String(id) },
      "vehicle " + id + " (" + kind + ", " + d.vehicles.cap[v] + " seat" + (d.vehicles.cap[v] > 1 ? "s" : "") + "): " +
      (run.labels[d.fleetStates[run.state[v]]] || "")));
    if (run.voxel) box.appendChild(el("div", null, "position " + run.px[v].toFixed(1) + ", " +
      run.py[v].toFixed(1) + ", altitude " + run.pz[v].toFixed(1) + " m"));
    var stops = [], riders = [];
    var F = (T && T.features) || {};
    var note = function (i, end) { // a booked ride; a rider who walks to or from the stop
      var s = "";
      if (end === "pickup" && F.booked && T.bk[i] === T.bk[i]) s += ", booked at " + clock(T.bk[i]);
      var m = !F.walks ? 0 : end === "pickup" ? T.wTo[i] : T.wFrom[i];
      if (m > 0) s += ", rider walks " + m.toFixed(0) + " m " + (end === "pickup" ? "to it" : "from it");
      return s ? " (" + s.slice(2) + ")" : "";
    };
    (run.tasksOf[id] || []).forEach(function (i) {
      var asg = T.asg ? fin(T.asg[i]) : T.rel[i], p = fin(T.pick[i]), cl = fin(T.close[i]);
      if (t >= cl) return;
      var drop = "drop-off of request " + T.id[i] + note(i, "dropoff");
      if (p <= t) {
        riders.push(i);
        if (T.dx[i] === T.dx[i]) stops.push([fin(T.done[i]), drop]);
      } else if (asg <= t) {
        stops.push([p, "pickup of request " + T.id[i] + note(i, "pickup")]);
        if (T.dx[i] === T.dx[i]) stops.push([fin(T.done[i]), drop]);
      }
    });
    stops.sort(function (a, b) { return a[0] - b[0]; });
    box.appendChild(el("div", null, "stop list:"));
    var ol = el("ol", { "data-panel": "stops" });
    if (!stops.length) ol.appendChild(el("li", { "class": "none" }, "no stops"));
    stops.forEach(function (s) {
      ol.appendChild(el("li", null, s[1] + (s[0] < Infinity ? " (at " + clock(s[0]) + ")" : "")));
    });
    box.appendChild(ol);
    box.appendChild(el("div", null, "riders: " + (riders.length ? riders.map(function (i) {
      return "request " + T.id[i] + (T.pax[i] > 1 ? " \u00d7" + T.pax[i] : ""); }).join(", ") : "none")));
    if (d.soc) {
      var q = run.socAt(t), sv = q ? d.soc.v[q.i * run.n + v] : 255;
      box.appendChild(el("div", null, "state of charge: " + (sv === 255 ? "\u2013" : (100 * sv / 250).toFixed(0) + " %")));
    }
    if (d.decisions) {
      var D = d.decisions, lo = D.off[v], hi = D.off[v + 1], n = 0, list = el("ol");
      for (var j = lo; j < hi; j++) if (D.t[j] <= t) n++;
      box.appendChild(el("div", null, "decisions that gave it a request: " + n));
      for (var m = Math.max(lo, lo + n - 6); m < lo + n; m++)
        list.appendChild(el("li", null, clock(D.t[m]) + ": request " + D.task[m] +
          (D.cost[m] === D.cost[m] ? ", cost " + D.cost[m].toFixed(1) + " s" : "")));
      box.appendChild(list);
    }
  };

  // ---------------------------------------------------------------- the application
  var LAYERS = { network: true, requests: true, arcs: true, flashes: true, trails: false, stations: true,
                 walks: true, offshift: false, transit: true };
  // [transit]: stations, riders aboard trains and riders walking to, from and between them
  var TRANSIT = { station: "#455a64", train: "#00838f", walk: "#2e7d32" };
  var runs = DATA.runs.map(function (d, i) { return new Run(d, i); });
  if (runs.some(function (r) { return r.voxel; })) LAYERS.trails = true;
  var root = document.getElementById("views");
  var views = runs.map(function (r) { return new View(r, root); });
  var T0 = Math.min.apply(null, runs.map(function (r) { return r.d.t0; }));
  var T1 = Math.max.apply(null, runs.map(function (r) { return r.d.t1; }));
  var APP = { t: T0, playing: false, speed: 10, dirty: true, frames: 0 };

  var scrub = document.getElementById("scrub"), clk = document.getElementById("clock");
  var playBtn = document.getElementById("play"), speedSel = document.getElementById("speed");
  scrub.min = String(T0); scrub.max = String(T1);
  [-10, -5, -1, 1, 5, 10, 30, 60].forEach(function (s) {
    var o = el("option", { value: String(s) }, s + "\u00d7"); if (s === 10) o.selected = true;
    speedSel.appendChild(o);
  });
  speedSel.addEventListener("change", function () { APP.speed = Number(speedSel.value); });
  function setPlaying(p) { APP.playing = p; playBtn.textContent = p ? "pause" : "play"; last = null; }
  playBtn.addEventListener("click", function () { setPlaying(!APP.playing); });
  document.addEventListener("keydown", function (e) {
    if (e.code === "Space" && e.target.tagName !== "INPUT") { e.preventDefault(); setPlaying(!APP.playing); }
  });
  scrub.addEventListener("input", function () { seek(Number(scrub.value)); });

  var jumpSel = document.getElementById("jumpkind"), kinds = {};
  runs.forEach(function (r) { for (var k in r.d.jumps) kinds[k] = true; });
  Object.keys(kinds).forEach(function (k) { jumpSel.appendChild(el("option", { value: k }, k)); });
  document.getElementById("jump").addEventListener("click", function () {
    var k = jumpSel.value, next = Infinity;
    runs.forEach(function (r) {
      var a = r.d.jumps[k]; if (!a) return;
      var i = ub(a, APP.t); if (i < a.length) next = Math.min(next, a[i]);
    });
    if (next < Infinity) { setPlaying(false); seek(next); }
  });
  var search = document.getElementById("search");
  function find() {
    var id = Number(search.value);
    views.forEach(function (v) { var i = v.run.byId[id]; v.setFollow(i === undefined ? -1 : i); });
  }
  document.getElementById("find").addEventListener("click", find);
  search.addEventListener("keydown", function (e) { if (e.key === "Enter") find(); });

  var layerBox = document.getElementById("layers");
  var layerNames = { network: runs.some(function (r) { return r.voxel; }) ? "map / obstacles" : "streets",
                     requests: "waiting requests", arcs: "rides (arcs)", flashes: "rejected / expired / declined",
                     trails: "trails", stations: "stations", walks: "walks", offshift: "off-shift vehicles",
                     transit: "subway stations, riders on trains and on foot" };
  function feature(f) { return runs.some(function (r) { return r.d.tasks && r.d.tasks.features && r.d.tasks.features[f]; }); }
  var hasShifts = runs.some(function (r) {
    var V = r.d.vehicles;
    for (var i = 0; i < V.stCode.length; i++) if (V.stCode[i] === r.offShift) return true;
    return false;
  });
  Object.keys(LAYERS).forEach(function (k) {
    if (k === "stations" && !runs.some(function (r) { return r.d.stations; })) return;
    if ((k === "walks" && !feature("walks")) || (k === "offshift" && !hasShifts)) return;
    if (k === "transit" && !runs.some(function (r) { return r.d.transit; })) return;
    var lab = el("label"), cb = el("input", { type: "checkbox", "data-layer": k });
    cb.checked = LAYERS[k];
    cb.addEventListener("change", function () { LAYERS[k] = cb.checked; views.forEach(function (v) { v.bgKey = ""; }); APP.dirty = true; });
    lab.appendChild(cb); lab.appendChild(document.createTextNode(" " + layerNames[k]));
    layerBox.appendChild(lab);
  });
  document.getElementById("meta").textContent = "dispatch " + DATA.version + " \u00b7 " +
    runs.map(function (r) { return r.d.runId; }).join(" vs ");
  document.title = "replay: " + runs.map(function (r) { return (r.d.scenario || "") + " " + r.d.runId; }).join(" vs ");

  var legend = document.getElementById("legend"), used = {};
  runs.forEach(function (r) {
    var V = r.d.vehicles;
    for (var i = 0; i < V.stCode.length; i++) used[V.stCode[i]] = true;
  });
  runs[0].d.fleetStates.forEach(function (s, i) {
    if (!used[i] && i > 4) return;
    var span = el("span", { "data-legend": s }), sw = el("span", { "class": "sw" }); sw.style.background = COLORS[s];
    span.appendChild(sw);
    span.appendChild(document.createTextNode(runs[0].labels[s] + (s === "off_shift" ? " – hidden; the layer shows rings at their depots" : "")));
    legend.appendChild(span);
  });
  var anyVoxel = runs.some(function (r) { return r.voxel; });
  [["request", "#ff7043", (anyVoxel ? "task waiting for a vehicle (hollow: a vehicle is on its way; circle: a task in the air)" :
                                      "request waiting for its pickup (hollow: a vehicle is on its way)"), true],
   ["booked", MARKS.booked, "booked ahead: diamond from booking to pickup (hollow: a promise a vehicle's plan holds)", feature("booked")],
   ["walk", MARKS.walk, "rider walking (dotted): origin to boarding point, alighting point to destination", feature("walks")],
   ["ride", "rgba(46,134,222,.6)", "ride: arc from pickup to drop-off while on board", true],
   ["refused", MARKS.refused, "request rejected or expired (flash)", true],
   ["declined", MARKS.declined, "offer declined by the rider (flash)", feature("offers")],
   ["station", TRANSIT.station, "subway station (ring)", runs.some(function (r) { return r.d.transit; })],
   ["train", TRANSIT.train, "rider aboard a train (dot, stop to stop)", runs.some(function (r) { return r.d.transit; })],
   ["on_foot", TRANSIT.walk, "rider walking to, from or between stations (small dot)",
    runs.some(function (r) { return r.d.transit; })]].forEach(function (x) {
    if (!x[3]) return;
    var span = el("span", { "data-legend": x[0] }), sw = el("span", { "class": "sw" }); sw.style.background = x[1];
    span.appendChild(sw); span.appendChild(document.createTextNode(x[2])); legend.appendChild(span);
  });
  legend.appendChild(el("span", { "class": "muted" }, runs.some(function (r) { return r.voxel; }) ?
    "triangle: ground robot (points where it drives); diamond: drone; grey boxes: obstacles, darker is taller" :
    "triangle: vehicle, pointing where it drives; grey lines: the run's street network"));

  function seek(t) {
    APP.t = Math.min(T1, Math.max(T0, Number(t)));
    APP.dirty = true;
    render();
  }
  function render() {
    views.forEach(function (v) { v.resize(); v.draw(APP.t); });
    scrub.value = String(APP.t);
    clk.textContent = clock(APP.t);
    APP.dirty = false;
  }
  var last = null;
  function frame(now) {
    APP.frames++;
    if (APP.playing) {
      if (last !== null) {
        var t = APP.t + (now - last) / 1000 * APP.speed;
        if (t >= T1 || t <= T0) { t = Math.min(T1, Math.max(T0, t)); setPlaying(false); }
        APP.t = t; APP.dirty = true;
      }
      last = now;
    }
    if (APP.dirty) render();
    requestAnimationFrame(frame);
  }
  window.addEventListener("resize", function () { APP.dirty = true; });

  function fromHash() {
    var m = /(?:^#|&)t=([0-9.eE+-]+)/.exec(location.hash || "");
    if (m && isFinite(Number(m[1]))) { setPlaying(false); seek(Number(m[1])); return true; }
    return false;
  }
  window.addEventListener("hashchange", fromHash);
  window.replay = {
    seek: function (t) { setPlaying(false); seek(t); return APP.t; },
    counts: function (i) { return runs[i || 0].counts(APP.t); },
    time: function () { return APP.t; },
    play: function (speed) { if (speed !== undefined) { APP.speed = Number(speed); speedSel.value = String(speed); } setPlaying(true); },
    pause: function () { setPlaying(false); },
    frames: function () { return APP.frames; },
    follow: function (id, i) { var v = views[i || 0], k = v.run.byId[id]; v.setFollow(k === undefined ? -1 : k); render(); return k !== undefined; },
    screen: function (id, i) { var v = views[i || 0], k = v.run.byId[id]; return k === undefined ? null : [v.sx(v.run.px[k]), v.sy(v.run.py[k])]; },
    vehicles: function (i) { // on-screen position (CSS pixels of the map) and state of each
      var v = views[i || 0], r = v.run, out = [];
      for (var k = 0; k < r.n; k++) out.push({ id: r.d.vehicles.id[k], x: v.sx(r.px[k]), y: v.sy(r.py[k]),
        state: r.d.fleetStates[r.state[k]], onboard: r.onb[k] });
      return out;
    },
    colors: COLORS,
    span: [T0, T1], version: DATA.version, runs: runs.map(function (r) { return r.d.runId; })
  };
  if (!fromHash()) seek(T0);
  APP.readyAt = performance.now();
  window.replay.readyAt = APP.readyAt; // milliseconds from navigation start to the first frame
  document.body.setAttribute("data-ready", "1");
  requestAnimationFrame(frame);
})();
