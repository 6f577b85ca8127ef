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

  // {hz, bytesPerSecond} over the window ending now.
  read(t = performance.now() / 1000) {
    this.trim(t);
    const bytes = this.samples.reduce((sum, [, b]) => sum + b, 0);
    return { hz: this.samples.length / WINDOW_S, bytesPerSecond: bytes / WINDOW_S };
  }
}
