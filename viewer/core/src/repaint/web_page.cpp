// The web page's viewer (web_export.hpp): HTML, CSS and script in one file,
// nothing fetched at run time. The script draws the look from look.js's
// planes: WebGL, one pass with a sampler per term; else a 2D canvas; else
// the still stays. Its HSH basis is hsh.hpp's, written out again.
#include "web_page.hpp"

#include <cstdint>

namespace veneer::repaint::web {
namespace {

// @OBJECT@, @MATERIAL@ (escaped), @WIDTH@, @HEIGHT@ are filled in.
constexpr const char* kPage = R"PAGE(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta http-equiv="Content-Security-Policy" content="default-src 'none'; script-src 'self' 'unsafe-inline'; img-src 'self' data:; style-src 'unsafe-inline'">
<title>@OBJECT@ in @MATERIAL@</title>
<style>
  html, body { margin: 0; background: #16161a; color: #e8e8ea; font: 16px/1.4 system-ui, sans-serif; }
  header { padding: 12px 16px 8px; }
  h1 { font-size: 1.3em; margin: 0; font-weight: 600; }
  header p { margin: 2px 0 0; color: #b8b8c0; }
  #view { position: relative; display: inline-block; max-width: 100%; margin: 0 16px; }
  #view img, #view canvas { display: block; max-width: 100%; height: auto; touch-action: none; cursor: crosshair; }
  #marker { position: absolute; width: 14px; height: 14px; margin: -7px 0 0 -7px; border-radius: 50%;
            background: #ffd76a; box-shadow: 0 0 0 2px #16161a; pointer-events: none; display: none; }
  .hint { padding: 8px 16px 16px; color: #9a9aa4; font-size: 0.9em; }
  body.bare header, body.bare .hint, body.bare #marker { display: none !important; }
  body.bare #view { margin: 0; }
  body.bare #view img, body.bare #view canvas { max-width: none; }
</style>
</head>
<body>
<header>
  <h1 id="object">@OBJECT@</h1>
  <p>in the material of <strong id="material">@MATERIAL@</strong></p>
</header>
<div id="view">
  <img id="still" src="still.jpg" width="@WIDTH@" height="@HEIGHT@" alt="@OBJECT@ in the material of @MATERIAL@">
  <canvas id="look" width="@WIDTH@" height="@HEIGHT@" style="display: none"></canvas>
  <div id="marker"></div>
</div>
<p class="hint" id="hint">Drag on the picture to move the light. Made with Veneer.</p>
<noscript><p class="hint">This picture relights when scripts run; without them it is shown under one light.</p></noscript>
<script src="look.js"></script>
<script>
(function () {
  'use strict';
  var L = window.VENEER_LOOK;
  var hint = document.getElementById('hint');
  var still = document.getElementById('still');
  var canvas = document.getElementById('look');
  var marker = document.getElementById('marker');
  if (!L) { hint.textContent = 'look.js is missing beside index.html: the picture is shown under one light.'; return; }

  // index.html#light=x,y (x right, y up, the unit disc), &bare (the picture alone at 1:1), &renderer=2d
  function readHash() {
    var out = { light: null, bare: false, renderer: '' };
    location.hash.replace(/^#/, '').split('&').forEach(function (kv) {
      var p = kv.split('=');
      if (p[0] === 'light' && p[1]) {
        var v = p[1].split(',').map(Number);
        if (v.length === 2 && isFinite(v[0]) && isFinite(v[1])) out.light = v;
      } else if (p[0] === 'bare') {
        out.bare = true;
      } else if (p[0] === 'renderer') {
        out.renderer = p[1] || '';
      }
    });
    return out;
  }

  // The hemispherical harmonics at the light (x, y) (hsh.hpp): theta off the
  // camera's axis, phi from x toward y.
  function basis(x, y) {
    var r = Math.sqrt(x * x + y * y);
    if (r > 1) { x /= r; y /= r; }
    var c = Math.sqrt(Math.max(0, 1 - x * x - y * y));
    var phi = Math.atan2(y, x), s = Math.sqrt(Math.max(0, c - c * c)), PI = Math.PI;
    var h = [1 / Math.sqrt(2 * PI),
             Math.sqrt(6 / PI) * Math.cos(phi) * s,
             Math.sqrt(3 / (2 * PI)) * (2 * c - 1),
             Math.sqrt(6 / PI) * Math.sin(phi) * s,
             Math.sqrt(30 / PI) * Math.cos(2 * phi) * (c * c - c),
             Math.sqrt(30 / PI) * Math.cos(phi) * (2 * c - 1) * s,
             Math.sqrt(5 / (2 * PI)) * (6 * c * c - 6 * c + 1),
             Math.sqrt(30 / PI) * Math.sin(phi) * (2 * c - 1) * s,
             Math.sqrt(30 / PI) * Math.sin(2 * phi) * (c * c - c)];
    return h.slice(0, L.terms);
  }

  // WebGL: one pass, plane K's texel t gives term K's coefficients (t - bias) * scale.
  function startGL() {
    var attrs = { preserveDrawingBuffer: true, antialias: false, premultipliedAlpha: false, alpha: false };
    var gl = canvas.getContext('webgl', attrs) || canvas.getContext('experimental-webgl', attrs);
    if (!gl) return null;
    var T = L.terms;
    if (gl.getParameter(gl.MAX_TEXTURE_IMAGE_UNITS) < T || gl.getParameter(gl.MAX_TEXTURE_SIZE) < Math.max(L.width, L.height)) return null;
    var vs = 'attribute vec2 p; varying vec2 uv;\n' +
             'void main() { uv = vec2(0.5 * (p.x + 1.0), 0.5 * (1.0 - p.y)); gl_Position = vec4(p, 0.0, 1.0); }\n';
    var fs = '#ifdef GL_FRAGMENT_PRECISION_HIGH\nprecision highp float;\n#else\nprecision mediump float;\n#endif\n' +
             'varying vec2 uv;\nuniform float h[' + T + '];\nuniform vec3 scale[' + T + '];\nuniform vec3 bias[' + T + '];\n';
    var k;
    for (k = 0; k < T; ++k) fs += 'uniform sampler2D plane' + k + ';\n';
    fs += 'void main() {\n  vec3 v = vec3(0.0);\n';
    for (k = 0; k < T; ++k) fs += '  v += h[' + k + '] * (texture2D(plane' + k + ', uv).rgb - bias[' + k + ']) * scale[' + k + '];\n';
    fs += '  gl_FragColor = vec4(clamp(v, 0.0, 1.0), 1.0);\n}\n';
    function shader(type, src) {
      var s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      return gl.getShaderParameter(s, gl.COMPILE_STATUS) ? s : null;
    }
    var v = shader(gl.VERTEX_SHADER, vs), f = shader(gl.FRAGMENT_SHADER, fs);
    if (!v || !f) return null;
    var prog = gl.createProgram();
    gl.attachShader(prog, v);
    gl.attachShader(prog, f);
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) return null;
    gl.useProgram(prog);
    var buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    var loc = gl.getAttribLocation(prog, 'p');
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 2, gl.FLOAT, false, 0, 0);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    var sc = [], bi = [];
    for (k = 0; k < T; ++k) {
      gl.activeTexture(gl.TEXTURE0 + k);
      gl.bindTexture(gl.TEXTURE_2D, gl.createTexture());
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB, gl.RGB, gl.UNSIGNED_BYTE, planes[k]);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      gl.uniform1i(gl.getUniformLocation(prog, 'plane' + k), k);
      for (var c = 0; c < 3; ++c) { sc.push(L.scale[3 * k + c]); bi.push(L.bias[3 * k + c]); }
    }
    if (gl.getError() !== gl.NO_ERROR) return null;
    gl.uniform3fv(gl.getUniformLocation(prog, 'scale'), new Float32Array(sc));
    gl.uniform3fv(gl.getUniformLocation(prog, 'bias'), new Float32Array(bi));
    var hl = gl.getUniformLocation(prog, 'h');
    gl.viewport(0, 0, L.width, L.height);
    return function (h) {
      gl.uniform1fv(hl, new Float32Array(h));
      gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    };
  }

  // A 2D canvas: the same sum on the CPU.
  function start2D() {
    var ctx = canvas.getContext('2d');
    if (!ctx) return null;
    var W = L.width, H = L.height, T = L.terms, data = [];
    try {
      planes.forEach(function (img) {
        var c = document.createElement('canvas');
        c.width = W;
        c.height = H;
        var x = c.getContext('2d');
        x.drawImage(img, 0, 0);
        data.push(x.getImageData(0, 0, W, H).data);
      });
    } catch (e) {
      return null;
    }
    var out = ctx.createImageData(W, H), d = out.data, n = W * H;
    return function (h) {
      var a = new Float32Array(3 * T), b = new Float32Array(3);
      for (var k = 0; k < T; ++k)
        for (var c = 0; c < 3; ++c) {
          a[3 * k + c] = h[k] * L.scale[3 * k + c] / 255;
          b[c] -= h[k] * L.scale[3 * k + c] * L.bias[3 * k + c];
        }
      for (var i = 0, o = 0; i < n; ++i, o += 4) {
        for (var ch = 0; ch < 3; ++ch) {
          var v = b[ch];
          for (var t = 0; t < T; ++t) v += data[t][o + ch] * a[3 * t + ch];
          d[o + ch] = v * 255;
        }
        d[o + 3] = 255;
      }
      ctx.putImageData(out, 0, 0);
    };
  }

  var planes = [], draw = null, light = L.first_light.slice(), frame = 0;
  var state = readHash();

  function show() {
    frame = 0;
    if (!draw) return;
    draw(basis(light[0], light[1]));
    var m = Math.min(canvas.clientWidth, canvas.clientHeight) / 2;
    marker.style.left = (canvas.clientWidth / 2 + light[0] * m) + 'px';
    marker.style.top = (canvas.clientHeight / 2 - light[1] * m) + 'px';
  }
  function request() { if (!frame) frame = requestAnimationFrame(show); }
  function applyHash() {
    state = readHash();
    document.body.classList.toggle('bare', state.bare);
    if (state.light) light = state.light;
    show();
  }

  function begin() {
    var renderer = 'webgl';
    if (state.renderer !== '2d') draw = startGL();
    if (!draw) { renderer = '2d'; draw = start2D(); }
    if (!draw) { hint.textContent = 'This browser cannot draw the picture: it is shown under one light.'; return; }
    still.style.display = 'none';
    canvas.style.display = 'block';
    marker.style.display = 'block';
    applyHash();
    document.body.setAttribute('data-renderer', renderer);
  }

  function onPointer(e) {
    if (e.type !== 'pointerdown' && !(e.buttons & 1)) return;
    e.preventDefault();
    var r = canvas.getBoundingClientRect(), m = Math.min(r.width, r.height) / 2;
    var x = (e.clientX - r.left - r.width / 2) / m, y = -(e.clientY - r.top - r.height / 2) / m;
    var len = Math.sqrt(x * x + y * y);
    if (len > 1) { x /= len; y /= len; }
    light = [x, y];
    history.replaceState(null, '', '#light=' + x.toFixed(3) + ',' + y.toFixed(3) + (state.bare ? '&bare' : ''));
    request();
  }
  canvas.addEventListener('pointerdown', onPointer);
  canvas.addEventListener('pointermove', onPointer);
  window.addEventListener('hashchange', applyHash);
  window.addEventListener('resize', request);
  document.body.classList.toggle('bare', state.bare);

  var left = L.planes.length;
  L.planes.forEach(function (src, k) {
    var img = new Image();
    img.onload = function () { if (--left === 0) begin(); };
    img.onerror = function () { hint.textContent = 'A plane of the picture did not decode: it is shown under one light.'; };
    img.src = src;
    planes[k] = img;
  });
})();
</script>
</body>
</html>
)PAGE";

void replace_all(std::string& s, const std::string& what, const std::string& with) {
  for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + with.size())) s.replace(at, what.size(), with);
}

}  // namespace

std::string html_escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string base64(const std::string& bytes) {
  static const char* const table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << 16 |
                       static_cast<uint32_t>(static_cast<uint8_t>(bytes[i + 1])) << 8 | static_cast<uint8_t>(bytes[i + 2]);
    out += table[v >> 18 & 63];
    out += table[v >> 12 & 63];
    out += table[v >> 6 & 63];
    out += table[v & 63];
  }
  if (i < bytes.size()) {
    uint32_t v = static_cast<uint32_t>(static_cast<uint8_t>(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<uint32_t>(static_cast<uint8_t>(bytes[i + 1])) << 8;
    out += table[v >> 18 & 63];
    out += table[v >> 12 & 63];
    out += i + 1 < bytes.size() ? table[v >> 6 & 63] : '=';
    out += '=';
  }
  return out;
}

std::string index_html(const std::string& object, const std::string& material, int width, int height) {
  std::string page = kPage;
  replace_all(page, "@OBJECT@", html_escape(object.empty() ? "The object" : object));
  replace_all(page, "@MATERIAL@", html_escape(material.empty() ? "the source" : material));
  replace_all(page, "@WIDTH@", std::to_string(width));
  replace_all(page, "@HEIGHT@", std::to_string(height));
  return page;
}

}  // namespace veneer::repaint::web
