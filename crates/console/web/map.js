// The map: world frame (x right, y up, metres) on a canvas, with pan and
// zoom by mouse and touch. Long paths are kept as Path2D objects in world
// coordinates at several levels of detail, and the static picture (grid,
// walls, paths) is drawn into an offscreen bitmap larger than the view:
// a frame while panning copies that bitmap and draws the live parts (the
// robots, beams, markers) on top, whatever the mission's length.

const LOD_TOLERANCES_M = [0, 0.004, 0.016, 0.064, 0.256];

// A path (columns x, y) as Path2D objects, one per level of detail; `ranges`
// (pairs of sample indices, inclusive) keeps only those stretches.
export class LodPath {
  constructor(cols, ranges) {
    this.levels = LOD_TOLERANCES_M.map((tol) => buildPath(cols.x, cols.y, ranges, tol));
    this.points = cols.x.length;
  }
  // The coarsest level finer than a pixel at `scale` px/m.
  pick(scale) {
    let best = this.levels[0];
    for (let i = 0; i < LOD_TOLERANCES_M.length; i++) {
      if (LOD_TOLERANCES_M[i] * scale <= 1) best = this.levels[i];
    }
    return best;
  }
}

function buildPath(xs, ys, ranges, tol) {
  const p = new Path2D();
  const spans = ranges || [[0, xs.length - 1]];
  const tol2 = tol * tol;
  for (const [a, b] of spans) {
    if (a > b || a >= xs.length) continue;
    let lx = xs[a], ly = ys[a];
    p.moveTo(lx, ly);
    const end = Math.min(b, xs.length - 1);
    for (let i = a + 1; i <= end; i++) {
      const dx = xs[i] - lx, dy = ys[i] - ly;
      if (i === end || dx * dx + dy * dy >= tol2) {
        p.lineTo(xs[i], ys[i]);
        lx = xs[i]; ly = ys[i];
      }
    }
  }
  return p;
}

// A plan's corridor as the console sends it: spokes [from_x, from_y, to_x,
// to_y, …] in order round the band, each a ray across the path from a
// point of it to the corridor's half width or the first wall, whichever is
// nearer (crates/console/src/corridor.rs). The band is the union of the
// quadrilaterals between each spoke and the next, each laid down as two
// triangles turning the same way, so the non-zero fill is their union
// however the path bends or crosses itself: no band over a wall's far side
// or an occupied cell. The map draws bands opaque, under the walls and
// paths.
export class Band {
  constructor(spokes) {
    this.path = new Path2D();
    const n = Math.floor(spokes.length / 4);
    const tri = (ax, ay, bx, by, cx, cy) => {
      const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
      if (area === 0) return;
      this.path.moveTo(ax, ay);
      if (area > 0) { this.path.lineTo(bx, by); this.path.lineTo(cx, cy); } else { this.path.lineTo(cx, cy); this.path.lineTo(bx, by); }
      this.path.closePath();
    };
    for (let k = 0; k < n; k++) {
      const i = 4 * k, j = 4 * ((k + 1) % n);
      const [cx, cy, ex, ey] = [spokes[i], spokes[i + 1], spokes[i + 2], spokes[i + 3]];
      const [dx, dy, fx, fy] = [spokes[j], spokes[j + 1], spokes[j + 2], spokes[j + 3]];
      tri(cx, cy, ex, ey, fx, fy);
      tri(cx, cy, fx, fy, dx, dy);
    }
    this.spokes = n;
  }
}

// The sample of `cols` at time `t` (columns t, x, y; t increasing), or null.
export function at(cols, t) {
  const ts = cols.t;
  if (!ts || ts.length === 0 || t < ts[0] || t > ts[ts.length - 1]) return null;
  let lo = 0, hi = ts.length - 1;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (ts[mid] <= t) lo = mid; else hi = mid - 1;
  }
  return [cols.x[lo], cols.y[lo]];
}

export class MapView {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.scale = 80; // px per metre
    this.cx = 0; this.cy = 0; // world point at the canvas centre
    this.layers = new Map(); // name -> { path: LodPath, style }
    this.dirty = true;
    this.grid = null; // offscreen canvas of the occupancy grid
    this.world = null;
    this.overlay = () => {}; // draws the live parts (robot, beams, markers)
    this.frameTimes = []; // ms per draw, the latest 600
    this.staticTimes = []; // ms per redraw of the static picture
    this.staticKey = 0; // changes with the world, the layers and their visibility
    this.cache = null;
    this.pointers = new Map();
    this.mode = null; // null | 'place' | 'region' | 'zone' | 'corridor'
    this.onPick = null; // (mode, startWorld, endWorld) => void
    // Outside a mode, a press the page claims (a zone's vertex): returns a
    // function that takes the pointer's world position as it moves, or null
    // to pan as usual. (world, pxInMetres) => ((world) => void) | null
    this.grab = null;
    this.drag = null;
    this.fitted = false;
    this.installInput();
    new ResizeObserver(() => { this.resize(); }).observe(canvas);
    this.resize();
    const loop = () => {
      if (this.dirty) this.draw();
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const r = this.canvas.getBoundingClientRect();
    const dpr = window.devicePixelRatio || 1;
    this.canvas.width = Math.max(1, Math.round(r.width * dpr));
    this.canvas.height = Math.max(1, Math.round(r.height * dpr));
    this.dpr = dpr;
    this.cache = null;
    this.dirty = true;
    // Until the operator pans or zooms, the whole site fits the view,
    // whatever the window's size.
    if (this.fitted && !this.moved && this.world?.bounds) this.fit(this.world.bounds);
  }

  setWorld(world) {
    this.world = world;
    this.grid = null;
    if (world.grid) {
      const g = world.grid;
      const c = document.createElement('canvas');
      c.width = g.width; c.height = g.height;
      const cx = c.getContext('2d');
      const img = cx.createImageData(g.width, g.height);
      for (let row = 0; row < g.height; row++) {
        for (let col = 0; col < g.width; col++) {
          const v = g.cells.charCodeAt(row * g.width + col) - 48;
          const shade = v === 1 ? 60 : v === 0 ? 255 : 205;
          // Image row 0 is the top: the grid's row 0 is the bottom.
          const k = ((g.height - 1 - row) * g.width + col) * 4;
          img.data[k] = img.data[k + 1] = img.data[k + 2] = shade;
          img.data[k + 3] = 255;
        }
      }
      cx.putImageData(img, 0, 0);
      this.grid = c;
    }
    this.staticKey++;
    if (!this.fitted && world.bounds) {
      this.fit(world.bounds);
      this.fitted = true;
    }
    this.dirty = true;
  }

  fit([x0, y0, x1, y1]) {
    const w = this.canvas.width / this.dpr, h = this.canvas.height / this.dpr;
    this.cx = (x0 + x1) / 2; this.cy = (y0 + y1) / 2;
    this.scale = Math.max(1, 0.9 * Math.min(w / Math.max(x1 - x0, 0.1), h / Math.max(y1 - y0, 0.1)));
    this.dirty = true;
  }

  setLayer(name, path, style) {
    if (path) this.layers.set(name, { path, style, visible: this.layers.get(name)?.visible ?? true });
    else this.layers.delete(name);
    this.staticKey++;
    this.dirty = true;
  }

  setVisible(group, on) {
    for (const [name, l] of this.layers) if (name === group || name.startsWith(group + ':')) l.visible = on;
    this.hidden = this.hidden || new Set();
    if (on) this.hidden.delete(group); else this.hidden.add(group);
    this.staticKey++;
    this.dirty = true;
  }

  isVisible(group) {
    return !(this.hidden && this.hidden.has(group));
  }

  // canvas px (CSS) -> world
  toWorld(px, py) {
    const w = this.canvas.width / this.dpr, h = this.canvas.height / this.dpr;
    return [this.cx + (px - w / 2) / this.scale, this.cy - (py - h / 2) / this.scale];
  }

  // Sets the world transform on ctx.
  worldTransform(ctx) {
    const w = this.canvas.width / this.dpr, h = this.canvas.height / this.dpr;
    const s = this.scale * this.dpr;
    ctx.setTransform(s, 0, 0, -s, (w / 2 - this.cx * this.scale) * this.dpr, (h / 2 + this.cy * this.scale) * this.dpr);
  }

  // Draws the static picture (grid, walls, every path layer) into `target`
  // with the world transform `t` = [scale (device px per m), ox, oy].
  drawStatic(ctx, t, pxScale) {
    ctx.setTransform(t[0], 0, 0, -t[0], t[1], t[2]);
    const px = 1 / pxScale; // one CSS pixel in metres
    const w = this.world;
    if (w) {
      if (this.grid) {
        const g = w.grid;
        ctx.save();
        ctx.translate(g.origin[0], g.origin[1]);
        ctx.rotate(g.origin[2]);
        ctx.scale(g.resolution_m, -g.resolution_m);
        ctx.imageSmoothingEnabled = false;
        ctx.drawImage(this.grid, 0, -g.height);
        ctx.restore();
      }
      this.drawBands(ctx);
      ctx.fillStyle = '#555';
      for (const [x0, y0, x1, y1] of w.solids) ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
      ctx.strokeStyle = '#222';
      ctx.lineWidth = 2.5 * px;
      ctx.beginPath();
      for (const [x0, y0, x1, y1] of w.segments) { ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); }
      ctx.stroke();
    }
    if (!w) this.drawBands(ctx);
    for (const [, l] of this.layers) {
      if (!l.visible || l.path instanceof Band) continue;
      ctx.strokeStyle = l.style.color;
      ctx.lineWidth = (l.style.width || 1.5) * px;
      ctx.setLineDash(l.style.dash ? l.style.dash.map((d) => d * px) : []);
      ctx.globalAlpha = l.style.alpha ?? 1;
      ctx.stroke(l.path.pick(pxScale));
    }
    ctx.setLineDash([]);
    ctx.globalAlpha = 1;
  }

  // Band layers (corridors), in their colour, opaque.
  drawBands(ctx) {
    for (const [, l] of this.layers) {
      if (!l.visible || !(l.path instanceof Band)) continue;
      ctx.fillStyle = l.style.color;
      ctx.fill(l.path.path, 'nonzero');
    }
  }

  // The static picture is drawn once into an offscreen canvas twice the
  // view's size each way, centred on the view; panning within it only
  // copies the bitmap. It is drawn again when the layers change, when the
  // view leaves it, or after a zoom settles (meanwhile the old one is
  // scaled: a long mission costs one redraw per zoom, not one per frame).
  renderStatic() {
    const t0 = performance.now();
    const W = this.canvas.width, H = this.canvas.height;
    const c = this.cacheCanvas || (this.cacheCanvas = document.createElement('canvas'));
    c.width = 2 * W; c.height = 2 * H;
    const ctx = c.getContext('2d');
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, c.width, c.height);
    const s = this.scale * this.dpr;
    // World point (cx, cy) at the cache's centre.
    this.drawStatic(ctx, [s, W - this.cx * s, H + this.cy * s], this.scale);
    this.cache = { key: this.staticKey, scale: this.scale, dpr: this.dpr, cx: this.cx, cy: this.cy, w: c.width, h: c.height };
    if (this.syncMeasure) ctx.getImageData(0, 0, 1, 1);
    const ms = performance.now() - t0;
    this.staticTimes.push(ms);
    if (this.staticTimes.length > 100) this.staticTimes.shift();
    this.lastStaticMs = ms;
  }

  cacheState() {
    const c = this.cache;
    if (!c || c.key !== this.staticKey || c.dpr !== this.dpr) return 'stale';
    // The view's half size in metres at the cache's scale, against the cache's.
    const vx = this.canvas.width / 2 / (this.scale * this.dpr), vy = this.canvas.height / 2 / (this.scale * this.dpr);
    const hx = c.w / 2 / (c.scale * c.dpr), hy = c.h / 2 / (c.scale * c.dpr);
    const inside = Math.abs(this.cx - c.cx) + vx <= hx && Math.abs(this.cy - c.cy) + vy <= hy;
    if (!inside) return 'outside';
    return c.scale === this.scale ? 'ok' : 'scaled';
  }

  scheduleSettle() {
    if (this.settle) return;
    const wait = () => {
      const still = performance.now() - (this.lastViewChange || 0);
      if (still < 150) {
        this.settle = setTimeout(wait, 150 - still);
        return;
      }
      this.settle = null;
      if (this.cacheState() !== 'ok') {
        this.renderStatic();
        this.dirty = true;
      }
    };
    this.settle = setTimeout(wait, 150);
  }

  draw() {
    const t0 = performance.now();
    this.dirty = false;
    const ctx = this.ctx;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = '#fff';
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    const state = this.cacheState();
    if (state === 'stale' || (state === 'outside' && !(this.lastStaticMs > 16))) {
      this.renderStatic();
    } else if (state !== 'ok') {
      // Expensive to redraw: show the old bitmap, redraw once the view has
      // been still for 150 ms (live updates do not postpone it).
      this.scheduleSettle();
    }
    const c = this.cache;
    // Cache pixel (u, v) shows world (c.cx + (u - w/2)/(c.scale dpr), ...).
    const k = this.scale / c.scale;
    const s = this.scale * this.dpr;
    const W = this.canvas.width, H = this.canvas.height;
    // Where the cache's centre lands on screen.
    const ux = W / 2 + (c.cx - this.cx) * s, uy = H / 2 - (c.cy - this.cy) * s;
    ctx.imageSmoothingEnabled = k !== 1;
    ctx.drawImage(this.cacheCanvas, ux - (c.w / 2) * k, uy - (c.h / 2) * k, c.w * k, c.h * k);
    this.worldTransform(ctx);
    const px = 1 / this.scale; // one CSS pixel in metres
    this.overlay(ctx, px);

    if (this.drag && this.drag.mode) {
      const [a, b] = [this.drag.start, this.drag.now];
      ctx.strokeStyle = '#805ad5';
      ctx.lineWidth = 2 * px;
      ctx.beginPath();
      if (this.drag.mode === 'region') ctx.arc(a[0], a[1], Math.hypot(b[0] - a[0], b[1] - a[1]), 0, 2 * Math.PI);
      else if (this.drag.mode === 'zone' || this.drag.mode === 'corridor') ctx.rect(a[0], a[1], b[0] - a[0], b[1] - a[1]);
      else { ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); }
      ctx.stroke();
    }
    // A benchmark asks for the raster itself to be timed: reading a pixel
    // back makes the browser finish drawing now, not at its next paint.
    if (this.syncMeasure) ctx.getImageData(0, 0, 1, 1);
    const dt = performance.now() - t0;
    this.frameTimes.push(dt);
    if (this.frameTimes.length > 600) this.frameTimes.shift();
  }

  installInput() {
    const c = this.canvas;
    c.addEventListener('wheel', (e) => {
      e.preventDefault();
      const r = c.getBoundingClientRect();
      this.zoomAt(e.clientX - r.left, e.clientY - r.top, Math.exp(-e.deltaY * 0.0015));
    }, { passive: false });
    c.addEventListener('pointerdown', (e) => {
      c.setPointerCapture(e.pointerId);
      const r = c.getBoundingClientRect();
      const p = [e.clientX - r.left, e.clientY - r.top];
      this.pointers.set(e.pointerId, p);
      const wpt = this.toWorld(...p);
      const held = !this.mode && this.pointers.size === 1 && this.grab ? this.grab(wpt, 1 / this.scale) : null;
      if (held) {
        this.drag = { held };
      } else if (this.mode && this.pointers.size === 1) {
        this.drag = { mode: this.mode, start: wpt, now: wpt };
      } else {
        this.drag = null;
      }
    });
    c.addEventListener('pointermove', (e) => {
      if (!this.pointers.has(e.pointerId)) return;
      const r = c.getBoundingClientRect();
      const p = [e.clientX - r.left, e.clientY - r.top];
      const old = this.pointers.get(e.pointerId);
      if (this.drag && this.drag.held) {
        this.drag.held(this.toWorld(...p));
        this.dirty = true;
      } else if (this.drag && this.drag.mode) {
        this.drag.now = this.toWorld(...p);
        this.dirty = true;
      } else if (this.pointers.size === 1) {
        this.pan(p[0] - old[0], p[1] - old[1]);
      } else if (this.pointers.size === 2) {
        const [a, b] = [...this.pointers.values()];
        const other = a === old ? b : a;
        const before = Math.hypot(old[0] - other[0], old[1] - other[1]);
        const after = Math.hypot(p[0] - other[0], p[1] - other[1]);
        if (before > 0) this.zoomAt((p[0] + other[0]) / 2, (p[1] + other[1]) / 2, after / before);
      }
      this.pointers.set(e.pointerId, p);
    });
    const end = (e) => {
      if (!this.pointers.has(e.pointerId)) return;
      this.pointers.delete(e.pointerId);
      if (this.drag && this.drag.mode && this.onPick) {
        const { mode, start, now } = this.drag;
        this.drag = null;
        this.onPick(mode, start, now);
      }
      this.drag = null;
      this.dirty = true;
    };
    c.addEventListener('pointerup', end);
    c.addEventListener('pointercancel', end);
  }

  pan(dx, dy) {
    this.moved = true;
    this.lastViewChange = performance.now();
    this.cx -= dx / this.scale;
    this.cy += dy / this.scale;
    this.dirty = true;
  }

  zoomAt(px, py, factor) {
    this.moved = true;
    this.lastViewChange = performance.now();
    const before = this.toWorld(px, py);
    this.scale = Math.min(5000, Math.max(2, this.scale * factor));
    const after = this.toWorld(px, py);
    this.cx += before[0] - after[0];
    this.cy += before[1] - after[1];
    this.dirty = true;
  }
}
