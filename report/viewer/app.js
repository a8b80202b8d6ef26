// The interactive view: the surrogate's forward pass in the page, drawn with three.js.
//
// The page carries its data in <script id="viewer-data" type="application/json">: the model as
// surrogate.export.export_web writes it, the surface triangles of the mesh, and FE solutions
// of some sweep cases. Nothing is fetched: the page works opened from the file system.
// window.viewer exposes the predictions and the timing to the browser test and the benchmark.
import {
  AmbientLight, ArrowHelper, BufferAttribute, BufferGeometry, Color, DirectionalLight,
  DoubleSide, Mesh, MeshBasicMaterial, MeshPhongMaterial, PerspectiveCamera, Raycaster, Scene,
  SphereGeometry, Vector2, Vector3, WebGLRenderer,
} from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const DATA = JSON.parse(document.getElementById('viewer-data').textContent);

// -- arrays ---------------------------------------------------------------------------------
const TYPES = { float32: Float32Array, int32: Int32Array, uint8: Uint8Array };

function decode(encoded) {
  const bytes = Uint8Array.from(atob(encoded.data), (ch) => ch.charCodeAt(0));
  return new TYPES[encoded.dtype](bytes.buffer);
}

// -- the surrogate (mirrors surrogate.predict.Surrogate) -------------------------------------
const SQRT_2_OVER_PI = Math.sqrt(2 / Math.PI);

// The unit gravity direction of (Φ, θ) in degrees, the paper's Eq. 1, as
// fem.dataset.gravity_direction: [cos Φ, sin Φ cos θ, sin Φ sin θ].
function gravityDirection(phi, theta) {
  const p = (phi * Math.PI) / 180;
  const t = (theta * Math.PI) / 180;
  return [Math.cos(p), Math.sin(p) * Math.cos(t), Math.sin(p) * Math.sin(t)];
}
const ACTIVATIONS = {
  tanh: Math.tanh,
  relu: (x) => (x > 0 ? x : 0),
  gelu: (x) => 0.5 * x * (1 + Math.tanh(SQRT_2_OVER_PI * (x + 0.044715 * x * x * x))),
  silu: (x) => x / (1 + Math.exp(-x)),
};

class WebSurrogate {
  constructor(model) {
    this.model = model;
    this.n = model.n_points;
    this.act = ACTIVATIONS[model.activation];
    this.X = decode(model.X_m);
    this.Xs = decode(model.points_standardised);
    this.separable = model.structure === 'separable' || model.structure === 'pod';
    if (this.separable) {
      // a separable model: its point networks give each point's fields once (evaluator), the
      // branch weighs them per query; a pod model carries its fields (modes) themselves
      const plain = (layers) => layers.map((layer) => {
        const [nIn, nOut] = layer.W.shape;
        return { W: decode(layer.W), b: decode(layer.b), nIn, nOut };
      });
      this.modes = model.modes;
      this.branch = plain(model.branch);
      // the point networks' Fourier frequencies (3 x F, row-major), as
      // surrogate.structures.separable's point_inputs: [X, sin 2πX·b, cos 2πX·b]
      this.frequencies = model.point_frequencies ? decode(model.point_frequencies) : null;
      this.parts = Object.values(model.parts).map((part) => ({
        points: decode(part.points),
        gain: decode(part.gain),
        layers: part.layers ? plain(part.layers) : null,
        modes: part.modes ? decode(part.modes) : null,
      }));
      this.range = model.training_range;
      return;
    }
    this.parts = Object.values(model.parts).map((part) => ({
      points: decode(part.points),
      gain: decode(part.gain),
      layers: part.layers.map((layer, l) => {
        const [nIn, nOut] = layer.W.shape;
        const W = decode(layer.W);
        if (l === 0) return { W, b: decode(layer.b), nIn, nOut };  // used per point, as it is
        // W transposed (row o holds the weights into output o): each output is then one dot
        // product over contiguous memory, summed in a local variable
        const Wt = new Float64Array(nIn * nOut);
        for (let k = 0; k < nIn; k += 1) {
          for (let o = 0; o < nOut; o += 1) Wt[o * nIn + k] = W[k * nOut + o];
        }
        return { Wt, b: decode(layer.b), nIn, nOut };
      }),
    })).map((part) => {
      if (model.output_form !== 'gravity_linear') return part;
      // the last layer contracted with the query's gravity direction: filled per query
      const { nIn } = part.layers[part.layers.length - 1];
      const contracted = { Wt: new Float64Array(3 * nIn), b: new Float64Array(3), nIn, nOut: 3 };
      return { ...part, contracted };
    });
    this.range = model.training_range;
  }

  // A gravity_linear model's last layer contracted with the gravity direction c[1..3]: its
  // nine outputs (the matrix M, row by row) become the three of M ĝ, as in Surrogate.predict.
  static contract(part, c) {
    const full = part.layers[part.layers.length - 1];
    const out = part.contracted;
    for (let i = 0; i < 3; i += 1) {
      out.b[i] = 0;
      for (let j = 0; j < 3; j += 1) out.b[i] += full.b[3 * i + j] * c[1 + j];
      for (let k = 0; k < full.nIn; k += 1) {
        let s = 0;
        for (let j = 0; j < 3; j += 1) s += full.Wt[(3 * i + j) * full.nIn + k] * c[1 + j];
        out.Wt[i * full.nIn + k] = s;
      }
    }
    return out;
  }

  // Encoded C1, gravity direction and output gain, as Surrogate.features computes them.
  features(C1, phi, theta) {
    const e = this.model.encoding;
    let enc = C1;
    if (e.c1 === 'log') enc = Math.log(C1);
    else if (e.c1 === 'inverse') enc = 1 / C1;
    const c = (2 * (enc - e.c1_min)) / (e.c1_max - e.c1_min) - 1;
    const gain = e.output_scaling === 'compliance' ? e.c1_ref / C1 : 1;
    return [c, ...gravityDirection(phi, theta), gain];
  }

  // An evaluator for the material points `indices`: the query-independent part of the first
  // layer is computed here, once; evaluate() then costs the rest.
  evaluator(indices) {
    const where = new Int32Array(this.n).fill(-1);
    indices.forEach((point, row) => { where[point] = row; });
    const parts = [];
    for (const part of this.parts) {
      const rows = [];
      const local = [];
      part.points.forEach((point, i) => {
        if (where[point] >= 0) { rows.push(where[point]); local.push(i); }
      });
      if (!rows.length) continue;
      if (this.separable) {  // the fields of these points, gain and 1/√modes included
        const m = 3 * this.modes;
        const scale = part.modes ? 1 : 1 / Math.sqrt(this.modes);  // a pod model's: its modes
        const fields = new Float32Array(rows.length * m);
        local.forEach((i, r) => {
          const point = part.points[i];
          const out = part.modes ? part.modes.subarray(i * m, (i + 1) * m)
            : WebSurrogate.dense(part.layers,
              this.pointInputs(this.Xs.subarray(3 * point, 3 * point + 3)), this.act);
          for (let j = 0; j < m; j += 1) fields[r * m + j] = out[j] * part.gain[i] * scale;
        });
        parts.push({ rows: Int32Array.from(rows), fields });
        continue;
      }
      const first = part.layers[0];
      const w = first.nOut;
      const pre = new Float32Array(rows.length * w);
      local.forEach((i, r) => {
        const point = part.points[i];
        for (let j = 0; j < w; j += 1) {
          let s = first.b[j];
          for (let k = 0; k < 3; k += 1) s += this.Xs[3 * point + k] * first.W[k * w + j];
          pre[r * w + j] = s;
        }
      });
      const widest = Math.max(...part.layers.map((l) => l.nOut));
      parts.push({
        rows: Int32Array.from(rows),
        gain: Float32Array.from(local, (i) => part.gain[i]),
        pre,
        layers: part.layers,
        contracted: part.contracted,
        q: new Float64Array(w),
        h: new Float64Array(rows.length * widest),
        g: new Float64Array(rows.length * widest),
      });
    }
    return { n: indices.length, parts, out: new Float32Array(3 * indices.length) };
  }

  // What a separable model's point networks see of a standardised point x (3 numbers).
  pointInputs(x) {
    if (!this.frequencies) return x;
    const f = this.frequencies.length / 3;
    const input = new Float64Array(3 + 2 * f);
    input.set(x);
    for (let j = 0; j < f; j += 1) {
      let z = 0;
      for (let k = 0; k < 3; k += 1) z += x[k] * this.frequencies[k * f + j];
      z *= 2 * Math.PI;
      input[3 + j] = Math.sin(z);
      input[3 + f + j] = Math.cos(z);
    }
    return input;
  }

  // Dense layers ({W, b, nIn, nOut}, W row-major) on one input, the activation between them.
  static dense(layers, input, act) {
    let h = input;
    layers.forEach((layer, l) => {
      const { W, b, nIn, nOut } = layer;
      const g = new Float64Array(nOut);
      for (let o = 0; o < nOut; o += 1) {
        let s = b[o];
        for (let k = 0; k < nIn; k += 1) s += h[k] * W[k * nOut + o];
        g[o] = l < layers.length - 1 ? act(s) : s;
      }
      h = g;
    });
    return h;
  }

  // A separable model's weights of its fields for case features c, as surrogate.model's
  // branch_weights: the branch network, its outputs contracted with ĝ in gravity_linear form.
  weights(c) {
    const h = WebSurrogate.dense(this.branch, c.slice(0, 4), this.act);
    if (this.model.output_form !== 'gravity_linear') return h;
    const w = new Float64Array(this.modes);
    for (let k = 0; k < this.modes; k += 1) {
      for (let j = 0; j < 3; j += 1) w[k] += h[3 * k + j] * c[1 + j];
    }
    return w;
  }

  // Displacement (mm) of the evaluator's points for one query, into ev.out (3 per point).
  evaluate(ev, C1, phi, theta) {
    const c = this.features(C1, phi, theta);
    const act = this.act;
    ev.out.fill(0);  // rib points of an exact-Dirichlet model stay zero
    if (this.separable) {
      const w = this.weights(c);
      const K = this.modes;
      for (const part of ev.parts) {
        const { rows, fields } = part;
        for (let i = 0; i < rows.length; i += 1) {
          for (let d = 0; d < 3; d += 1) {
            const f = (3 * i + d) * K;
            let s = 0;
            for (let k = 0; k < K; k += 1) s += fields[f + k] * w[k];
            ev.out[3 * rows[i] + d] = s * c[4];
          }
        }
      }
      return ev.out;
    }
    for (const part of ev.parts) {
      const n = part.rows.length;
      const first = part.layers[0];
      const w = first.nOut;
      const q = part.q;
      for (let j = 0; j < w; j += 1) {
        q[j] = 0;
        for (let k = 0; k < 4; k += 1) q[j] += c[k] * first.W[(3 + k) * w + j];
      }
      let h = part.h;
      let g = part.g;
      for (let i = 0; i < n; i += 1) {
        for (let j = 0; j < w; j += 1) h[i * w + j] = act(part.pre[i * w + j] + q[j]);
      }
      const last = part.layers.length - 1;
      for (let l = 1; l <= last; l += 1) {
        const contract = l === last && part.contracted;
        const { Wt, b, nIn, nOut } = contract ? WebSurrogate.contract(part, c) : part.layers[l];
        const hidden = l < last;
        // four points at a time share each weight they load; each sum keeps the order of one
        let i = 0;
        for (; i + 3 < n; i += 4) {
          const ha = i * nIn;
          const hb = ha + nIn;
          const hc = hb + nIn;
          const hd = hc + nIn;
          const go = i * nOut;
          for (let o = 0; o < nOut; o += 1) {
            const wo = o * nIn;
            let sa = b[o];
            let sb = sa;
            let sc = sa;
            let sd = sa;
            for (let k = 0; k < nIn; k += 1) {
              const wk = Wt[wo + k];
              sa += h[ha + k] * wk;
              sb += h[hb + k] * wk;
              sc += h[hc + k] * wk;
              sd += h[hd + k] * wk;
            }
            g[go + o] = hidden ? act(sa) : sa;
            g[go + nOut + o] = hidden ? act(sb) : sb;
            g[go + 2 * nOut + o] = hidden ? act(sc) : sc;
            g[go + 3 * nOut + o] = hidden ? act(sd) : sd;
          }
        }
        for (; i < n; i += 1) {
          const hi = i * nIn;
          const go = i * nOut;
          for (let o = 0; o < nOut; o += 1) {
            const wo = o * nIn;
            let s = b[o];
            for (let k = 0; k < nIn; k += 1) s += h[hi + k] * Wt[wo + k];
            g[go + o] = hidden ? act(s) : s;
          }
        }
        [h, g] = [g, h];
      }
      for (let i = 0; i < n; i += 1) {
        const scale = part.gain[i] * c[4];
        const r = 3 * part.rows[i];
        for (let d = 0; d < 3; d += 1) ev.out[r + d] = h[3 * i + d] * scale;
      }
    }
    return ev.out;
  }

  // A query in a one-plane model's plane under the plane's own name, as TrainingRange.plane_name:
  // gravity at (Φ, θ0 + 180°) is gravity at (−Φ, θ0).
  planeName(phi, theta) {
    const r = this.range;
    if (r.directions || r.theta_deg.length !== 1 || Math.abs(theta - r.theta_deg[0]) < 1e-6) {
      return [phi, theta];
    }
    const t0 = (r.theta_deg[0] * Math.PI) / 180;
    const g = gravityDirection(phi, theta);
    if (Math.abs(g[2] * Math.cos(t0) - g[1] * Math.sin(t0)) > 1e-9) return [phi, theta];
    const along = g[1] * Math.cos(t0) + g[2] * Math.sin(t0);
    return [Math.round((Math.atan2(along, g[0]) * 180 * 1e6) / Math.PI) / 1e6 + 0, r.theta_deg[0]];
  }

  // The reasons a query is an extrapolation, in the words of Surrogate._warn_if_outside
  // (numbers as Python prints a float: 7.0, 0.8).
  warnings(C1, givenPhi, givenTheta) {
    const r = this.range;
    const py = (x) => (Number.isInteger(x) ? x.toFixed(1) : String(x));
    const given = `Φ = ${py(givenPhi)}°, θ = ${py(givenTheta)}°`;
    const [phi, theta] = this.planeName(givenPhi, givenTheta);
    const renamed = phi !== givenPhi || theta !== givenTheta;
    const messages = [];
    const [lo, hi] = r.c1_kPa;
    if ((lo !== null && C1 < lo - 1e-9) || (hi !== null && C1 > hi + 1e-9)) {
      messages.push(`C1 = ${py(C1)} kPa is outside the training range [${py(lo)}, ${py(hi)}] kPa`);
    }
    const mod = (a) => ((a % 360) + 360) % 360;
    if (r.phi_gap) {
      const [start, width] = r.phi_gap;
      const offset = mod(phi - start);
      if (offset > 1e-6 && offset < width - 1e-6) {
        const named = renamed ? `gravity at ${given} (Φ = ${py(phi)}° in the trained plane)`
          : `Φ = ${py(phi)}°`;
        messages.push(`${named} lies in a ${width.toFixed(0)}° arc without training angles`);
      }
    }
    if (r.directions) {
      const g = gravityDirection(phi, theta);
      const cos = Math.max(...r.directions.map((d) => d[0] * g[0] + d[1] * g[1] + d[2] * g[2]));
      const nearest = (Math.acos(Math.min(Math.max(cos, -1), 1)) * 180) / Math.PI;
      if (nearest > r.direction_reach_deg) {
        messages.push(`gravity at Φ = ${py(phi)}°, θ = ${py(theta)}° is ${nearest.toFixed(0)}° from `
          + 'the nearest training direction (they are '
          + `${r.direction_spacing_deg.toFixed(0)}° apart)`);
      }
    }
    if (r.theta_deg.length === 1 && Math.abs(Math.sin((phi * Math.PI) / 180)) > 1e-6
        && Math.abs(theta - r.theta_deg[0]) > 1e-6) {
      messages.push(`θ = ${py(theta)}° but the surrogate was trained at θ = ${py(r.theta_deg[0])}° `
        + 'only');
    }
    // as Surrogate._beside: off the plane, the entries within one typical spacing of the
    // query's direction; in the plane, those at the sweep angles on either side
    const beside = (cases) => {
      if (!cases.length) return [];
      if (r.directions) {
        const g = gravityDirection(phi, theta);
        return cases.filter(([, p, t]) => {
          const d = gravityDirection(p, t);
          const cos = Math.min(Math.max(d[0] * g[0] + d[1] * g[1] + d[2] * g[2], -1), 1);
          return (Math.acos(cos) * 180) / Math.PI <= r.direction_spacing_deg + 1e-9;
        });
      }
      const q = mod(phi);
      const angles = r.sweep_phi_deg;
      const below = angles.reduce((a, p) => (mod(q - p) < mod(q - a) ? p : a));
      const above = angles.reduce((a, p) => (mod(p - q) < mod(a - q) ? p : a));
      const near = (p, n) => Math.abs(mod(p - n + 180) - 180) < 1e-6;
      return cases.filter(([, p, t]) => Math.abs(t - theta) < 1e-6
        && (near(p, below) || near(p, above)));
    };
    // the greatest (C1, Φ, θ) as Python's max of tuples
    const later = (a, b) => b[0] > a[0] || (b[0] === a[0] && (b[1] > a[1]
      || (b[1] === a[1] && b[2] > a[2])));
    const greatest = (cases) => cases.reduce((a, b) => (later(a, b) ? b : a));
    const at = (p, t) => (r.directions ? `Φ = ${p}°, θ = ${t}°` : `Φ = ${p}°`);
    let failed = false;
    const unconverged = beside(r.unconverged);
    if (unconverged.length) {
      const [c1, p, t] = greatest(unconverged);
      if (C1 <= c1 + 1e-9) {
        failed = true;
        messages.push(`the sweep's FE solve did not converge at C1 = ${c1} kPa, ${at(p, t)} `
          + `(beside C1 = ${py(C1)} kPa, ${given}), so no FE solution `
          + `backs C1 ≤ ${c1} kPa there`);
      }
    }
    // as TrainingRange.softest_beside: a direction beside the query trained only at stiffer C1
    const stiffer = beside(r.softest).filter(([c1]) => C1 < c1 - 1e-9);
    if (!failed && !(lo !== null && C1 < lo - 1e-9) && stiffer.length) {
      const [c1, p, t] = greatest(stiffer);
      messages.push(`the sweep's softest FE solution at ${at(p, t)} (beside C1 = ${py(C1)} kPa, `
        + `${given}) is at C1 = ${c1} kPa, so no FE solution backs `
        + `C1 < ${c1} kPa there`);
    }
    return messages.map((m) => `${m}; the prediction is an extrapolation`);
  }
}

// -- colours --------------------------------------------------------------------------------
// viridis at nine stops (matplotlib's table), interpolated linearly
const VIRIDIS = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
  [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]].map((c) => c.map((v) => v / 255));

function colourmap(t, out, offset) {
  const x = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(x), VIRIDIS.length - 2);
  const f = x - i;
  for (let d = 0; d < 3; d += 1) out[offset + d] = VIRIDIS[i][d] * (1 - f) + VIRIDIS[i + 1][d] * f;
}

function niceCeiling(value) {
  if (!(value > 0)) return 1;
  const step = 10 ** Math.floor(Math.log10(value));
  return [1, 2, 2.5, 5, 10].map((m) => m * step).find((v) => v >= value);
}

// -- the scene ------------------------------------------------------------------------------
const surrogate = new WebSurrogate(DATA.model);
const surface = decode(DATA.surface.points);        // material-point index of each vertex
const triangles = decode(DATA.surface.triangles);   // vertex indices, 3 per triangle
const nv = surface.length;
const onSurface = surrogate.evaluator(Array.from(surface));
const onSurfaceFrom = surrogate.evaluator(Array.from(surface));  // the start posture's, apart
const everywhere = surrogate.evaluator(Array.from({ length: surrogate.n }, (_, i) => i));
const feCases = DATA.fe_cases.map((c) => ({ ...c, u: decode(c.u_mm),
  innerU: c.inner_u_mm ? decode(c.inner_u_mm) : null }));
// named points inside the body (a tumour's centre and margin): the model at those points
const inner = DATA.inner ? new WebSurrogate(DATA.inner.model) : null;
const innerNames = DATA.inner ? DATA.inner.names : [];
const inside = inner ? inner.evaluator(Array.from({ length: inner.n }, (_, i) => i)) : null;
const insideFrom = inner ? inner.evaluator(Array.from({ length: inner.n }, (_, i) => i)) : null;
// the postures a movement can be measured from (the select's options after "rest")
const starts = DATA.starts || [];

const reference = new Float32Array(3 * nv);
const magnitude = new Float32Array(nv);
for (let v = 0; v < nv; v += 1) {
  for (let d = 0; d < 3; d += 1) reference[3 * v + d] = 1000 * surrogate.X[3 * surface[v] + d];
}
const geometry = new BufferGeometry();
const positions = new BufferAttribute(new Float32Array(reference), 3);
const colours = new BufferAttribute(new Float32Array(3 * nv), 3);
geometry.setAttribute('position', positions);
geometry.setAttribute('color', colours);
geometry.setIndex(new BufferAttribute(Uint32Array.from(triangles), 1));
geometry.computeBoundingSphere();
const centre = geometry.boundingSphere.center.clone();
const radius = geometry.boundingSphere.radius;

const canvas = document.getElementById('view');
const renderer = new WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
const scene = new Scene();
scene.background = new Color(0xf4f4f2);
const camera = new PerspectiveCamera(35, 1, radius / 100, radius * 40);
camera.up.set(0, 0, 1);  // z is cranial
camera.position.copy(centre).add(new Vector3(-2.2 * radius, 2.2 * radius, 1.1 * radius));
scene.add(new AmbientLight(0xffffff, 1.1));
const light = new DirectionalLight(0xffffff, 1.6);
light.position.set(-1, 1, 2);
scene.add(light);
const breast = new Mesh(geometry, new MeshPhongMaterial({
  vertexColors: true, side: DoubleSide, shininess: 15,
}));
scene.add(breast);
const arrowAnchor = centre.clone().add(new Vector3(0, -1.25 * radius, 0.75 * radius));
const gravityArrow = new ArrowHelper(new Vector3(1, 0, 0), arrowAnchor, 0.7 * radius, 0xc0392b,
  0.2 * radius, 0.1 * radius);
scene.add(gravityArrow);
const controls = new OrbitControls(camera, canvas);
controls.target.copy(centre);

function resize() {
  const { clientWidth: w, clientHeight: h } = canvas;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}

// -- state and controls ---------------------------------------------------------------------
const $ = (id) => document.getElementById(id);
const inputs = { C1: $('c1'), phi: $('phi'), theta: $('theta') };
const [c1Lo, c1Hi] = surrogate.range.c1_kPa;
inputs.C1.min = String(Math.max(0.05, 0.5 * (c1Lo ?? 1)));
inputs.C1.max = String(1.5 * (c1Hi ?? 5));
// start: the posture the movement is measured from ({name, phi, theta}, at the sliders' C1),
// or null for rest
const state = { mode: 'surrogate', fe: null, points: [], lastMs: 0,
  start: starts.find((s) => s.selected) || null };
let current = null;  // surrogate displacement of the surface vertices, mm

function query() {
  return { C1: Number(inputs.C1.value), phi: Number(inputs.phi.value),
    theta: Number(inputs.theta.value) };
}

// the FE case at this C1 whose gravity is the query's, under any name: Φ = -180° is 180°, and
// (Φ, θ + 180°) is (-Φ, θ)
function matchingFeCase({ C1, phi, theta }) {
  const g = gravityDirection(phi, theta);
  return feCases.find((c) => Math.abs(c.C1 - C1) < 1e-6
    && Math.hypot(...gravityDirection(c.phi, c.theta).map((x, d) => x - g[d])) < 1e-6) || null;
}

function update() {
  const began = performance.now();
  const q = query();
  current = surrogate.evaluate(onSurface, q.C1, q.phi, q.theta);
  state.fe = matchingFeCase(q);
  const mode = state.fe ? state.mode : 'surrogate';
  const shown = mode === 'fe' ? state.fe.u : current;
  // The movement from a start posture at the same C1: the surrogate's in the surrogate mode;
  // in the FE modes where the page carries the FE case of the start posture too (feFrom).
  const feFrom = state.start && mode !== 'surrogate'
    ? matchingFeCase({ C1: q.C1, phi: state.start.phi, theta: state.start.theta }) : null;
  const start = state.start && (mode === 'surrogate' || feFrom) ? state.start : null;
  const from = start ? surrogate.evaluate(onSurfaceFrom, q.C1, start.phi, start.theta) : null;
  let largest = 0;
  for (let v = 0; v < nv; v += 1) {
    let s = 0;
    for (let d = 0; d < 3; d += 1) {
      const i = 3 * v + d;
      positions.array[i] = reference[i] + shown[i];
      const sur = current[i] - (from ? from[i] : 0);
      const fe = state.fe ? state.fe.u[i] - (feFrom ? feFrom.u[i] : 0) : 0;
      const diff = { surrogate: sur, fe, difference: sur - fe }[mode];
      s += diff * diff;
    }
    magnitude[v] = Math.sqrt(s);
    largest = Math.max(largest, magnitude[v]);
  }
  const top = niceCeiling(largest);
  for (let v = 0; v < nv; v += 1) colourmap(magnitude[v] / top, colours.array, 3 * v);
  positions.needsUpdate = true;
  colours.needsUpdate = true;
  const g = new Vector3(...gravityDirection(q.phi, q.theta));
  gravityArrow.setDirection(g);  // drawn beside the body, centred on its anchor
  gravityArrow.position.copy(arrowAnchor).addScaledVector(g, -0.35 * radius);
  placePoints(mode, inner ? inner.evaluate(inside, q.C1, q.phi, q.theta) : null,
    from && inner ? inner.evaluate(insideFrom, q.C1, start.phi, start.theta) : null, from, feFrom);
  renderer.render(scene, camera);
  state.lastMs = performance.now() - began;
  showState(q, mode, top, largest, start, feFrom);
}

function showState(q, mode, top, largest, start, feFrom) {
  $('c1-value').textContent = `${q.C1.toFixed(2)} kPa`;
  $('phi-value').textContent = `${q.phi.toFixed(0)}°`;
  $('theta-value').textContent = `${q.theta.toFixed(0)}°`;
  const title = { surrogate: '|u|, surrogate', fe: '|u|, FE', difference: '|u surrogate − u FE|' };
  const moved = { surrogate: 'movement, surrogate', fe: 'movement, FE',
    difference: '|Δx surrogate − Δx FE|' };
  $('scale-title').textContent = start ? `${moved[mode]}, from ${start.name} (mm)`
    : `${title[mode]} (mm)`;
  [0, 0.25, 0.5, 0.75, 1].forEach((f, i) => {
    // three significant digits without trailing zeros: 100, 62.5, 0.25
    $(`tick-${i}`).textContent = String(Number((f * top).toPrecision(3)));
  });
  $('max-value').textContent = `largest ${largest.toFixed(2)} mm`;
  $('timing').textContent = `update ${state.lastMs.toFixed(1)} ms`;
  const warnings = surrogate.warnings(q.C1, q.phi, q.theta).concat(start
    ? surrogate.warnings(q.C1, start.phi, start.theta).map((w) => `from ${start.name}: ${w}`)
    : []);
  $('warnings').textContent = warnings.join('\n');
  $('warnings').hidden = !warnings.length;
  $('fe-controls').classList.toggle('disabled', !state.fe);
  // the select names the FE case the sliders sit on, however they got there
  $('fe-case').value = state.fe ? String(feCases.indexOf(state.fe)) : '';
  for (const radio of document.querySelectorAll('input[name=mode]')) radio.disabled = !state.fe;
  $('fe-note').textContent = state.fe ? `FE case ${state.fe.id}`
    : 'choose an FE case to compare (the sliders then sit on a solved case)';
  let note = start ? `grey: where the points are ${start.name}; blue: where they are now; the `
    + 'table and colours give the movement between them' : '';
  if (feFrom) note = `FE from the case ${feFrom.id}; ${note}`;
  else if (state.start && !start) {
    note = `no FE case ${state.start.name} at C1 = ${q.C1.toFixed(2)} kPa in this page: the FE `
      + 'modes show the movement from rest';
  }
  $('start-note').textContent = note;
}

// -- named points ---------------------------------------------------------------------------
const pointGeometry = new SphereGeometry(radius / 30, 16, 12);
const fixed1 = (x) => x.toFixed(1).replace(/^-(0\.0)$/, '$1');  // no "-0.0"
const fixed3 = (x) => x.toFixed(3).replace(/^-(0\.000)$/, '$1');
// one row of the points' table; a difference (small) to the micrometre
const row = (name, colour, u, small = false) => `<tr><td><span style="color:${colour}">●</span> `
  + `${name}</td><td>${Math.hypot(...u).toFixed(small ? 3 : 2)}</td>`
  + `<td>${u.map(small ? fixed3 : fixed1).join(', ')}</td></tr>`;
const escapeHtml = (text) => text.replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
// the named points inside: grey at rest, blue where the surrogate (or, in the FE mode, the
// FE case where the page carries it there) moves them
const innerMarkers = innerNames.map((name, i) => {
  const ref = new Mesh(pointGeometry, new MeshBasicMaterial({ color: 0x8a8a8a }));
  ref.position.set(...[0, 1, 2].map((d) => 1000 * inner.X[3 * i + d]));
  const deformed = new Mesh(pointGeometry, new MeshBasicMaterial({ color: 0x1f77b4 }));
  scene.add(ref, deformed);
  return { name: escapeHtml(name), colour: '#1f77b4', ref, deformed };
});
// Each point where the mode's field moves it. The table lists that displacement, or from a
// start posture the movement from it (the grey marker then stands where the point is in that
// posture); in the difference mode, the surrogate's minus the FE case's. A field at the points
// is `now` (the sliders' posture) and `before` (the start's: zero from rest), for the surrogate
// and, where the page carries it, for FE.
function placePoints(mode, innerSurrogate, innerFrom, from, feFrom) {
  const at = (field, k) => (field ? [0, 1, 2].map((d) => field[3 * k + d]) : [0, 0, 0]);
  const place = (point, origin, now, before) => {
    point.deformed.position.set(...origin.map((x, d) => x + now[d]));
    point.ref.position.set(...origin.map((x, d) => x + before[d]));
    return row(point.name, point.colour, now.map((x, d) => x - before[d]));
  };
  const compare = (point, sur, surBefore, fe, feBefore, origin) => {
    point.deformed.position.set(...origin.map((x, d) => x + sur[d]));
    point.ref.position.set(...origin.map((x, d) => x + surBefore[d]));
    return row(point.name, point.colour, sur.map((x, d) => x - surBefore[d] - fe[d] + feBefore[d]),
      true);
  };
  // by the mode, where FE is known at the point (fe: null where the page has no FE there)
  const show = (point, origin, sur, surBefore, fe, feBefore) => {
    if (mode === 'difference' && fe) return compare(point, sur, surBefore, fe, feBefore, origin);
    return mode === 'fe' && fe ? place(point, origin, fe, feBefore)
      : place(point, origin, sur, surBefore);
  };
  const rows = innerMarkers.map((point, i) => show(point, at(inner.X, i).map((x) => 1000 * x),
    at(innerSurrogate, i), at(innerFrom, i),
    state.fe && state.fe.innerU ? at(state.fe.innerU, i) : null,
    at(feFrom && feFrom.innerU, i)));
  for (const point of state.points) {
    const v = point.vertex;
    rows.push(show(point, at(reference, v), at(current, v), at(from, v),
      state.fe ? at(state.fe.u, v) : null, at(feFrom && feFrom.u, v)));
  }
  const moving = Boolean(from);
  $('points').innerHTML = rows.join('');
  $('points-size').textContent = (mode === 'difference' && '|Δu| mm') || (moving && '|Δx| mm')
    || '|u| mm';
  $('points-u').textContent = (mode === 'difference'
    && (moving ? 'Δx surrogate − Δx FE (mm)' : 'u surrogate − u FE (mm)'))
    || (moving && 'Δx (x, y, z) mm') || 'u (x, y, z) mm';
}

function seeThrough(on) {
  const material = breast.material;
  material.transparent = on;
  material.opacity = on ? 0.35 : 1;
  material.depthWrite = !on;
  material.needsUpdate = true;
  renderer.render(scene, camera);
}

function addPoint(vertex) {
  const name = `P${state.points.length + 1}`;
  const ref = new Mesh(pointGeometry, new MeshBasicMaterial({ color: 0x8a8a8a }));
  ref.position.set(...[0, 1, 2].map((d) => reference[3 * vertex + d]));
  const deformed = new Mesh(pointGeometry, new MeshBasicMaterial({ color: 0xd62728 }));
  scene.add(ref, deformed);
  state.points.push({ name, colour: '#d62728', vertex, ref, deformed });
  update();
}

const raycaster = new Raycaster();
let pressed = null;
canvas.addEventListener('pointerdown', (e) => { pressed = [e.clientX, e.clientY]; });
canvas.addEventListener('pointerup', (e) => {
  if (!pressed || Math.hypot(e.clientX - pressed[0], e.clientY - pressed[1]) > 4) return;
  const rect = canvas.getBoundingClientRect();
  const at = new Vector2(((e.clientX - rect.left) / rect.width) * 2 - 1,
    -((e.clientY - rect.top) / rect.height) * 2 + 1);
  raycaster.setFromCamera(at, camera);
  const hit = raycaster.intersectObject(breast)[0];
  if (!hit) return;
  const { a, b, c } = hit.face;
  const nearest = [a, b, c].reduce((best, v) => {
    const d = hit.point.distanceTo(new Vector3().fromBufferAttribute(positions, v));
    return d < best[1] ? [v, d] : best;
  }, [a, Infinity])[0];
  addPoint(nearest);
});

// -- wiring ---------------------------------------------------------------------------------
function setQuery(C1, phi, theta) {
  inputs.C1.value = String(C1);
  inputs.phi.value = String(phi);
  inputs.theta.value = String(theta);
  update();
}

for (const input of Object.values(inputs)) input.addEventListener('input', update);
for (const button of document.querySelectorAll('[data-phi]')) {
  button.addEventListener('click', () => setQuery(inputs.C1.value, button.dataset.phi,
    button.dataset.theta));
}
const select = $('fe-case');
feCases.forEach((c, i) => {
  const option = document.createElement('option');
  option.value = String(i);
  option.textContent = c.label;
  select.appendChild(option);
});
select.addEventListener('change', () => {
  const c = feCases[Number(select.value)];
  if (c) setQuery(c.C1, c.phi, c.theta);
});
// the movement's start: rest, a posture, or the sliders' posture when chosen (kept as its own
// option, so that choosing "here" again fixes the sliders' new posture)
function setStart(value) {
  const select = $('start');
  if (value === 'here') {
    const q = query();
    const name = `Φ = ${q.phi.toFixed(0)}°, θ = ${q.theta.toFixed(0)}°`;
    let fixed = select.querySelector('option[value=fixed]');
    if (!fixed) {
      fixed = document.createElement('option');
      fixed.value = 'fixed';
      select.insertBefore(fixed, select.querySelector('option[value=here]'));
    }
    fixed.textContent = name;
    state.start = { name, phi: q.phi, theta: q.theta };
    select.value = 'fixed';
  } else if (value !== 'fixed') {
    state.start = value === 'rest' ? null : starts[Number(value)];
    select.value = value;
  }
  update();
}
$('start').addEventListener('change', (e) => setStart(e.target.value));
for (const radio of document.querySelectorAll('input[name=mode]')) {
  radio.addEventListener('change', () => { state.mode = radio.value; update(); });
}
if ($('see-through')) {
  $('see-through').addEventListener('change', (e) => seeThrough(e.target.checked));
  seeThrough($('see-through').checked);
}
controls.addEventListener('change', () => renderer.render(scene, camera));
window.addEventListener('resize', () => { resize(); renderer.render(scene, camera); });
resize();
update();

// -- for the browser test and the benchmark ------------------------------------------------
window.viewer = {
  ready: true,
  nPoints: surrogate.n,
  nSurface: nv,
  // displacement (mm) of every material point, in the model's order
  predictAll: (C1, phi, theta) => Array.from(surrogate.evaluate(everywhere, C1, phi, theta)),
  // displacement (mm) of the named points inside, in their order (empty without them)
  innerNames,
  predictInner: (C1, phi, theta) => (inner
    ? Array.from(inner.evaluate(inside, C1, phi, theta)) : []),
  // the table of points as shown: [name, |u|, u] per row
  pointRows: () => Array.from(document.querySelectorAll('#points tr'),
    (tr) => Array.from(tr.cells, (td) => td.textContent.replace(/^● /, ''))),
  warnings: (C1, phi, theta) => surrogate.warnings(C1, phi, theta),
  setQuery,
  addPoint,
  setStart,
  state: () => ({ ...query(), mode: state.fe ? state.mode : 'surrogate',
    start: state.start && state.start.name,
    fe: state.fe && state.fe.id, lastMs: state.lastMs,
    seeThrough: breast.material.transparent,
    warnings: $('warnings').hidden ? [] : $('warnings').textContent.split('\n') }),
  // n predictions at the surface vertices alone (no drawing), in ms
  benchmarkPrediction: (n) => {
    const times = [];
    for (let i = 0; i < n; i += 1) {
      const start = performance.now();
      surrogate.evaluate(onSurface, Number(inputs.C1.value), -180 + ((37 * i) % 360), 0);
      times.push(performance.now() - start);
    }
    return times;
  },
  // n updates (prediction on the surface, colours, one frame drawn and finished), in ms
  benchmark: (n) => {
    const gl = renderer.getContext();
    const times = [];
    for (let i = 0; i < n; i += 1) {
      const start = performance.now();
      inputs.phi.value = String(-180 + ((37 * i) % 360));
      update();
      gl.finish();
      times.push(performance.now() - start);
    }
    return times;
  },
};
