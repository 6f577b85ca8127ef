// Message rate and bandwidth measured in the page over a sliding window.

const WINDOW_S = 2;

export class Meter {
  constructor() {
    this.samples = []; // [t, bytes]
  }

  record(bytes, t = performance.now() / 1000) {
    this.samples.push([t, bytes]);
    this.trim(t);
  }

  trim(t) {
    while (this.samples.length && this.samples[0][0] < t - WINDOW_S) this.samples.shift();
  }

  // {hz, bytesPerSecond} over the window ending now, and what `ros2 topic hz` and
  // `ros2 topic bw` print of it: the intervals' min, max and standard deviation
  // (seconds), the window's message count, the mean, min and max message size (bytes).
  read(t = performance.now() / 1000) {
    this.trim(t);
    const bytes = this.samples.reduce((sum, [, b]) => sum + b, 0);
    const gaps = this.samples.slice(1).map(([at], i) => at - this.samples[i][0]);
    const mean = gaps.length ? gaps.reduce((a, b) => a + b, 0) / gaps.length : 0;
    const variance = gaps.length ? gaps.reduce((a, g) => a + (g - mean) ** 2, 0) / gaps.length : 0;
    const sizes = this.samples.map(([, b]) => b);
    return {
      hz: this.samples.length / WINDOW_S,
      bytesPerSecond: bytes / WINDOW_S,
      window: this.samples.length,
      minGap: gaps.length ? Math.min(...gaps) : 0,
      maxGap: gaps.length ? Math.max(...gaps) : 0,
      stdDev: Math.sqrt(variance),
      meanSize: sizes.length ? bytes / sizes.length : 0,
      minSize: sizes.length ? Math.min(...sizes) : 0,
      maxSize: sizes.length ? Math.max(...sizes) : 0,
    };
  }
}
