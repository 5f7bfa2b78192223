"""An image viewer inside a self-contained HTML page, for comparing two renders as tev does.

:func:`viewer` returns an HTML fragment that shows two linear images (the
user's and the reference, or the tracer's and Mitsuba's) and their relative
difference; :func:`assets` the style and script that every page including
viewers carries once. Everything is in the page: the images travel as their
float32 values (zlib-compressed, base64), decoded by the browser's own
``DecompressionStream``, so hovering shows the values themselves, not their
8-bit picture, and nothing is fetched from anywhere.

What a reader can do, modelled on tev (Tom's EXR viewer, github.com/Tom94/tev):

* hover: the pixel's coordinates, both images' linear R, G, B and their
  relative difference sum_c |a - b| / max(sum_c |b|, floor) (the floor as in
  :func:`reference.verdicts.compare.pixel_relative_difference`);
* click, or the space bar or F: flip between the two images; 1, 2, 3 show the
  first, the second, the difference (false colour on a log scale from 1e-8 to
  1, the ``inferno`` map of the heat maps); E and Shift+E: exposure up and down
  by half a stop;
* the mouse wheel zooms around the pointer, dragging pans, Shift+dragging a
  rectangle zooms onto that region, R or a double click resets the view.

Keys act on the viewer the pointer is over (or was last over).
"""

from __future__ import annotations

import base64
import html
import itertools
import json
import zlib

import numpy as np

_COUNTER = itertools.count()


def _inferno_hex(n: int = 256) -> str:
    import matplotlib

    c = matplotlib.colormaps["inferno"](np.linspace(0, 1, n))[:, :3]
    return "".join(f"{int(round(v * 255)):02x}" for rgb in c for v in rgb)


def encode_image(image: np.ndarray) -> str:
    """H x W x 3 float32 values, zlib-compressed, in base64 (what the page decodes)."""
    data = np.ascontiguousarray(np.nan_to_num(image, nan=0.0, posinf=3.4e38, neginf=-3.4e38),
                                dtype="<f4")
    return base64.b64encode(zlib.compress(data.tobytes(), 6)).decode("ascii")


def viewer(images: list[tuple[str, np.ndarray]], caption: str = "",
           marks: np.ndarray | None = None, vid: str | None = None) -> str:
    """An HTML fragment showing two images (name, H x W x 3 linear) and their difference.

    ``marks`` (H x W booleans, optional) are pixels to outline in the
    difference view (those that failed a check).
    """
    if len(images) != 2:
        raise ValueError("the viewer compares exactly two images")
    h, w = images[0][1].shape[:2]
    for _, img in images:
        if img.shape[:2] != (h, w):
            raise ValueError("the two images differ in size")
    vid = vid or f"wv{next(_COUNTER)}"
    names = [n for n, _ in images]
    data = [encode_image(img) for _, img in images]
    mark = ""
    if marks is not None and marks.any():
        packed = np.packbits(np.asarray(marks, dtype=bool).ravel())
        mark = base64.b64encode(zlib.compress(packed.tobytes(), 6)).decode("ascii")
    esc = html.escape
    scale = max(1, min(4, 480 // max(w, 1)))
    return (
        f"<div class='wv' id='{esc(vid)}' data-width='{w}' data-height='{h}' "
        f"data-names='{esc(json.dumps(names))}' data-scale='{scale}' tabindex='0'>"
        f"<div class='wv-bar'><span class='wv-shown'></span> "
        f"<button type='button' data-show='0'>1: {esc(names[0])}</button>"
        f"<button type='button' data-show='1'>2: {esc(names[1])}</button>"
        f"<button type='button' data-show='2'>3: relative difference</button>"
        f"<span class='wv-exposure'></span></div>"
        f"<canvas class='wv-canvas' width='{w * scale}' height='{h * scale}'></canvas>"
        f"<div class='wv-readout'>hover for values</div>"
        f"<div class='wv-help'>click / space / F: flip &middot; 1 2 3: pick &middot; wheel: zoom "
        f"&middot; drag: pan &middot; shift+drag: zoom on a region &middot; R / double click: "
        f"reset &middot; E / shift+E: exposure</div>"
        + (f"<div class='wv-caption'>{esc(caption)}</div>" if caption else "")
        + "".join(f"<script type='application/octet-stream' class='wv-data' "
                  f"data-index='{i}'>{d}</script>" for i, d in enumerate(data))
        + (f"<script type='application/octet-stream' class='wv-marks'>{mark}</script>"
           if mark else "")
        + "</div>")


_CSS = """
.wv { display: inline-block; margin: 8px 0; outline: none; font-size: 12px; }
.wv-bar { margin-bottom: 4px; } .wv-bar button { font-size: 12px; margin-right: 2px; }
.wv-bar button.on { font-weight: 700; background: #dde6ff; }
.wv-shown { font-weight: 600; margin-right: 6px; } .wv-exposure { color: #555; margin-left: 6px; }
.wv-canvas { display: block; border: 1px solid #999; cursor: crosshair; background: #222;
             image-rendering: pixelated; max-width: 100%; }
.wv-readout { font: 12px/1.4 ui-monospace, monospace; min-height: 3em; white-space: pre; }
.wv-help, .wv-caption { color: #666; font-size: 11px; max-width: 640px; }
"""

_JS = r"""
(function () {
  var LUT = '%LUT%';
  var lut = new Uint8Array(LUT.length / 2);
  for (var i = 0; i < lut.length; i++) lut[i] = parseInt(LUT.substr(2 * i, 2), 16);
  var active = null;
  function b64(s) {
    var bin = atob(s.trim()), out = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  function inflate(bytes) {
    var ds = new DecompressionStream('deflate');
    var stream = new Blob([bytes]).stream().pipeThrough(ds);
    return new Response(stream).arrayBuffer();
  }
  function srgb(x) {
    x = x <= 0 ? 0 : (x >= 1 ? 1 : x);
    return x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
  }
  function fmt(v) {
    if (!isFinite(v)) return String(v);
    var a = Math.abs(v);
    return (a !== 0 && (a < 1e-3 || a >= 1e5)) ? v.toExponential(4) : v.toPrecision(5);
  }
  function Viewer(el) {
    this.el = el;
    this.w = +el.dataset.width; this.h = +el.dataset.height;
    this.names = JSON.parse(el.dataset.names);
    this.canvas = el.querySelector('.wv-canvas');
    this.ctx = this.canvas.getContext('2d');
    this.readout = el.querySelector('.wv-readout');
    this.shownEl = el.querySelector('.wv-shown');
    this.expEl = el.querySelector('.wv-exposure');
    this.shown = 0; this.exposure = 0;
    this.zoom = 1; this.ox = 0; this.oy = 0;    // image pixel at the canvas's top left
    this.images = [null, null]; this.marks = null;
    var self = this;
    var blobs = el.querySelectorAll('.wv-data');
    var jobs = Array.prototype.map.call(blobs, function (s) {
      return inflate(b64(s.textContent)).then(function (buf) {
        self.images[+s.dataset.index] = new Float32Array(buf);
      });
    });
    var mk = el.querySelector('.wv-marks');
    if (mk) jobs.push(inflate(b64(mk.textContent)).then(function (buf) {
      self.marks = new Uint8Array(buf);
    }));
    Promise.all(jobs).then(function () { self.ready(); }, function (e) {
      el.setAttribute('data-error', String(e)); self.readout.textContent = 'cannot decode: ' + e;
    });
  }
  Viewer.prototype.ready = function () {
    var w = this.w, h = this.h, a = this.images[0], b = this.images[1];
    var sum = 0;
    for (var i = 0; i < w * h * 3; i++) sum += Math.abs(b[i]);
    this.floor = 1e-3 * Math.max(sum / (w * h), 1e-30);
    this.rel = new Float64Array(w * h);
    for (var p = 0; p < w * h; p++) {
      var num = 0, den = 0;
      for (var c = 0; c < 3; c++) {
        num += Math.abs(a[3 * p + c] - b[3 * p + c]);
        den += Math.abs(b[3 * p + c]);
      }
      this.rel[p] = num / Math.max(den, this.floor);
    }
    this.off = document.createElement('canvas');
    this.off.width = w; this.off.height = h;
    this.bind();
    this.show(0);
    this.el.setAttribute('data-ready', '1');
  };
  Viewer.prototype.paint = function () {
    var w = this.w, h = this.h, img = this.off.getContext('2d').createImageData(w, h);
    var d = img.data, k = Math.pow(2, this.exposure);
    if (this.shown < 2) {
      var src = this.images[this.shown];
      for (var p = 0; p < w * h; p++) for (var c = 0; c < 3; c++)
        d[4 * p + c] = Math.round(255 * srgb(k * src[3 * p + c]));
    } else {
      var lo = Math.log(1e-8), hi = Math.log(1);
      for (var q = 0; q < w * h; q++) {
        var t = (Math.log(Math.min(Math.max(this.rel[q], 1e-8), 1)) - lo) / (hi - lo);
        var j = Math.round(t * (lut.length / 3 - 1)) * 3;
        var m = this.marks && (this.marks[q >> 3] >> (7 - (q & 7))) & 1;
        d[4 * q] = m ? 0 : lut[j]; d[4 * q + 1] = m ? 255 : lut[j + 1];
        d[4 * q + 2] = m ? 255 : lut[j + 2];
      }
    }
    for (var z = 0; z < w * h; z++) d[4 * z + 3] = 255;
    this.off.getContext('2d').putImageData(img, 0, 0);
    this.draw();
  };
  Viewer.prototype.draw = function () {
    var s = this.scale();
    this.ctx.imageSmoothingEnabled = false;
    this.ctx.fillStyle = '#222';
    this.ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    this.ctx.drawImage(this.off, -this.ox * s, -this.oy * s, this.w * s, this.h * s);
    this.el.setAttribute('data-zoom', this.zoom.toFixed(4));
    this.el.setAttribute('data-view', this.ox.toFixed(3) + ',' + this.oy.toFixed(3));
  };
  Viewer.prototype.scale = function () { return this.canvas.width / this.w * this.zoom; };
  Viewer.prototype.show = function (k) {
    this.shown = k;
    var label = k < 2 ? this.names[k] : 'relative difference';
    this.shownEl.textContent = label;
    this.el.setAttribute('data-shown', label);
    var buttons = this.el.querySelectorAll('button[data-show]');
    for (var i = 0; i < buttons.length; i++) {
      buttons[i].classList.toggle('on', +buttons[i].dataset.show === k);
    }
    var sign = this.exposure >= 0 ? '+' : '';
    this.expEl.textContent = 'exposure ' + sign + this.exposure.toFixed(1);
    this.paint();
  };
  Viewer.prototype.pixelAt = function (ev) {
    var r = this.canvas.getBoundingClientRect();
    var cx = (ev.clientX - r.left) * this.canvas.width / r.width;
    var cy = (ev.clientY - r.top) * this.canvas.height / r.height;
    var s = this.scale();
    return [this.ox + cx / s, this.oy + cy / s];
  };
  Viewer.prototype.hover = function (ev) {
    var p = this.pixelAt(ev), x = Math.floor(p[0]), y = Math.floor(p[1]);
    if (x < 0 || y < 0 || x >= this.w || y >= this.h) { this.readout.textContent = ''; return; }
    var i = 3 * (y * this.w + x), a = this.images[0], b = this.images[1];
    var lines = ['pixel ' + x + ', ' + y];
    for (var k = 0; k < 2; k++) {
      var src = this.images[k];
      lines.push(this.names[k] + ': ' + [src[i], src[i + 1], src[i + 2]].map(fmt).join(' '));
    }
    lines.push('relative difference: ' + fmt(this.rel[y * this.w + x]));
    this.readout.textContent = lines.join('\n');
    this.el.setAttribute('data-hover', x + ',' + y);
  };
  Viewer.prototype.zoomAt = function (cx, cy, f) {   // canvas position (cx, cy) stays put
    var s = this.scale(), px = this.ox + cx / s, py = this.oy + cy / s;
    this.zoom = Math.min(Math.max(this.zoom * f, 1), 256);
    s = this.scale();
    this.ox = px - cx / s; this.oy = py - cy / s;
    this.draw();
  };
  Viewer.prototype.reset = function () { this.zoom = 1; this.ox = 0; this.oy = 0; this.draw(); };
  Viewer.prototype.key = function (ev) {
    var k = ev.key;
    if (k === ' ' || k === 'f' || k === 'F') this.show(this.shown === 0 ? 1 : 0);
    else if (k === '1' || k === '2' || k === '3') this.show(+k - 1);
    else if (k === 'r' || k === 'R') this.reset();
    else if (k === 'e') { this.exposure += 0.5; this.show(this.shown); }
    else if (k === 'E') { this.exposure -= 0.5; this.show(this.shown); }
    else return;
    ev.preventDefault();
  };
  Viewer.prototype.bind = function () {
    var self = this, c = this.canvas, drag = null;
    function canvasXY(ev) {
      var r = c.getBoundingClientRect();
      return [(ev.clientX - r.left) * c.width / r.width,
              (ev.clientY - r.top) * c.height / r.height];
    }
    c.addEventListener('mousemove', function (ev) {
      active = self; self.hover(ev);
      if (drag) {
        var xy = canvasXY(ev);
        if (Math.abs(xy[0] - drag.x) + Math.abs(xy[1] - drag.y) > 3) drag.moved = true;
        if (drag.moved && !drag.rect) {
          var s = self.scale();
          self.ox = drag.ox - (xy[0] - drag.x) / s; self.oy = drag.oy - (xy[1] - drag.y) / s;
          self.draw();
        } else if (drag.moved) {
          self.draw();
          self.ctx.strokeStyle = '#4af'; self.ctx.lineWidth = 2;
          self.ctx.strokeRect(drag.x, drag.y, xy[0] - drag.x, xy[1] - drag.y);
        }
      }
    });
    c.addEventListener('mouseenter', function () { active = self; });
    c.addEventListener('mousedown', function (ev) {
      var xy = canvasXY(ev);
      drag = {x: xy[0], y: xy[1], ox: self.ox, oy: self.oy, moved: false, rect: ev.shiftKey};
      ev.preventDefault();
    });
    window.addEventListener('mouseup', function (ev) {
      if (!drag) return;
      var d = drag; drag = null;
      if (!d.moved) { if (ev.target === c) self.show(self.shown === 0 ? 1 : 0); return; }
      if (d.rect) {
        var xy = canvasXY(ev), s = self.scale();
        var x0 = Math.min(d.x, xy[0]), y0 = Math.min(d.y, xy[1]);
        var bw = Math.abs(xy[0] - d.x), bh = Math.abs(xy[1] - d.y);
        var f = Math.min(c.width / bw, c.height / bh);
        self.ox = self.ox + x0 / s; self.oy = self.oy + y0 / s;
        self.zoom = Math.min(Math.max(self.zoom * f, 1), 256);
        self.draw();
      }
    });
    c.addEventListener('dblclick', function () { self.reset(); });
    c.addEventListener('wheel', function (ev) {
      var xy = canvasXY(ev);
      self.zoomAt(xy[0], xy[1], ev.deltaY < 0 ? 1.25 : 0.8);
      self.hover(ev);
      ev.preventDefault();
    }, {passive: false});
    this.el.addEventListener('keydown', function (ev) { self.key(ev); });
    var buttons = this.el.querySelectorAll('button[data-show]');
    for (var i = 0; i < buttons.length; i++) buttons[i].addEventListener('click', function (ev) {
      self.show(+ev.currentTarget.dataset.show);
    });
  };
  document.addEventListener('keydown', function (ev) {
    if (active && !active.el.contains(document.activeElement)) active.key(ev);
  });
  function start() {
    var all = document.querySelectorAll('.wv');
    window.whittedViewers = Array.prototype.map.call(all, function (el) { return new Viewer(el); });
  }
  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', start);
  else start();
})();
"""


def assets() -> str:
    """The ``<style>`` and ``<script>`` a page with viewers carries once (in its head)."""
    return f"<style>{_CSS}</style><script>{_JS.replace('%LUT%', _inferno_hex())}</script>"
