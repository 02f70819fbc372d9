// The last minute of the solve on a 2D canvas: each second's mean time per solve stage,
// stacked (left axis, ms), and the solved frame rate facecapd reports (right axis, fps).

export const kGraphSeconds = 60;
// The solve's stages in the order they run (core/frame.hpp SolveStage); the stream's JSON
// object arrives sorted by name.
const kStageOrder = ['stabilise', 'correspond', 'weights', 'blend', 'rhs', 'backsolve', 'collide', 'filter'];
const kStageColours = ['#4e79a7', '#f28e2b', '#e15759', '#76b7b2', '#59a14f', '#edc948', '#b07aa1', '#ff9da7'];

export class SolveGraph {
  constructor(canvas, legend) {
    this.canvas = canvas;
    this.legend = legend;
    this.seconds = [];  // {t, stages: {name: mean_us}, fps}
    this.current = null;
    this.stageNames = [];
    this.fps = 0;
  }

  // A frame's stage times (µs), from the stream.
  addFrame(nowSeconds, stageUs) {
    const t = Math.floor(nowSeconds);
    if (!this.current || this.current.t !== t) {
      if (this.current) this.close(this.current);
      this.current = { t, sums: {}, n: 0 };
    }
    for (const [name, us] of Object.entries(stageUs)) {
      this.current.sums[name] = (this.current.sums[name] ?? 0) + us;
      if (!this.stageNames.includes(name)) {
        this.stageNames.push(name);
        const rank = (n) => (kStageOrder.includes(n) ? kStageOrder.indexOf(n) : kStageOrder.length);
        this.stageNames.sort((a, b) => rank(a) - rank(b));
      }
    }
    this.current.n += 1;
  }

  // The status window's solved fps.
  setFps(fps) {
    this.fps = fps;
  }

  close(bucket) {
    const stages = {};
    for (const [name, sum] of Object.entries(bucket.sums)) stages[name] = sum / bucket.n;
    this.seconds.push({ t: bucket.t, stages, fps: this.fps });
    while (this.seconds.length && this.seconds[0].t <= bucket.t - kGraphSeconds) this.seconds.shift();
    this.draw();
  }

  draw() {
    const c = this.canvas, g = c.getContext('2d');
    const width = (c.width = c.clientWidth * devicePixelRatio), height = (c.height = c.clientHeight * devicePixelRatio);
    g.scale(devicePixelRatio, devicePixelRatio);
    const w = c.clientWidth, h = c.clientHeight, left = 42, right = 40, top = 8, bottom = 18;
    g.clearRect(0, 0, width, height);
    g.font = '11px system-ui, sans-serif';
    g.fillStyle = '#9aa3ad';
    g.strokeStyle = '#2c323a';
    if (!this.seconds.length) {
      g.fillText('waiting for frames...', left, top + 20);
      return;
    }
    const totals = this.seconds.map((s) => Object.values(s.stages).reduce((a, b) => a + b, 0) / 1000);
    const maxMs = Math.max(0.1, ...totals) * 1.15;
    const maxFps = Math.max(1, ...this.seconds.map((s) => s.fps)) * 1.15;
    const tEnd = this.seconds[this.seconds.length - 1].t;
    const x = (t) => left + ((t - (tEnd - kGraphSeconds + 1)) / (kGraphSeconds - 1)) * (w - left - right);
    const yMs = (ms) => top + (1 - ms / maxMs) * (h - top - bottom);
    const yFps = (fps) => top + (1 - fps / maxFps) * (h - top - bottom);
    for (let i = 0; i <= 4; ++i) {
      const y = top + (i / 4) * (h - top - bottom);
      g.beginPath();
      g.moveTo(left, y);
      g.lineTo(w - right, y);
      g.stroke();
      g.fillText(((maxMs * (4 - i)) / 4).toFixed(2), 2, y + 4);
      g.fillText(((maxFps * (4 - i)) / 4).toFixed(0), w - right + 4, y + 4);
    }
    g.fillText('ms', 2, h - 4);
    g.fillText('fps', w - right + 4, h - 4);
    g.fillText(`last ${kGraphSeconds} s`, left, h - 4);
    // The stages stacked, in the solve's order.
    const base = this.seconds.map(() => 0);
    this.stageNames.forEach((name, k) => {
      g.fillStyle = kStageColours[k % kStageColours.length];
      g.beginPath();
      this.seconds.forEach((s, i) => g.lineTo(x(s.t), yMs((base[i] + (s.stages[name] ?? 0)) / 1000)));
      for (let i = this.seconds.length - 1; i >= 0; --i) g.lineTo(x(this.seconds[i].t), yMs(base[i] / 1000));
      g.closePath();
      g.fill();
      this.seconds.forEach((s, i) => (base[i] += s.stages[name] ?? 0));
    });
    g.strokeStyle = '#ffffff';
    g.lineWidth = 1.5;
    g.beginPath();
    this.seconds.forEach((s) => g.lineTo(x(s.t), yFps(s.fps)));
    g.stroke();
    this.legend.replaceChildren(
      ...this.stageNames.map((name, k) => {
        const item = document.createElement('span');
        item.innerHTML = `<i style="background:${kStageColours[k % kStageColours.length]}"></i>${name}`;
        return item;
      }),
      Object.assign(document.createElement('span'), { innerHTML: '<i style="background:#fff"></i>fps' }),
    );
  }
}
