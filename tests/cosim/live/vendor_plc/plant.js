"use strict";
/**
 * The four-tank process (the project's plant: fmus/fourtank/model.c, section V of Schimperna
 * & Magni, parameters of Alvarado et al. 2011), integrated with a fixed-step classical
 * Runge-Kutta method: the vendor PLC's own process, written independently of the FMU.
 *
 *   dh1/dt = (-a1 sqrt(2 g h1) + a3 sqrt(2 g h3) + gamma_a qa)       / S
 *   dh2/dt = (-a2 sqrt(2 g h2) + a4 sqrt(2 g h4) + gamma_b qb)       / S
 *   dh3/dt = (-a3 sqrt(2 g h3)                   + (1 - gamma_b) qb) / S
 *   dh4/dt = (-a4 sqrt(2 g h4)                   + (1 - gamma_a) qa) / S
 *
 * Levels [m] never go negative (an empty tank has no outflow and stays empty).
 */

const PARAMETERS = Object.freeze({
  S: 0.06, a: [1.31e-4, 1.51e-4, 9.27e-5, 8.82e-5], gammaA: 0.3, gammaB: 0.4, g: 9.81,
});

/** The operating point the FMU starts at: h1 = h2 = 0.65 m, an equilibrium for (qa, qb). */
const START = Object.freeze({
  h: [0.65, 0.65, 0.6514031296511584, 0.6638294000727866],
  qa: 4.5472443083696316e-4,
  qb: 5.523354343150548e-4,
});

/** dh/dt at levels h for pump flows qa, qb [m3/s]. */
function derivatives(h, qa, qb, p = PARAMETERS) {
  const out = h.map((level, i) => p.a[i] * Math.sqrt(2 * p.g * Math.max(level, 0)));
  const inflow = [
    out[2] + p.gammaA * qa,
    out[3] + p.gammaB * qb,
    (1 - p.gammaB) * qb,
    (1 - p.gammaA) * qa,
  ];
  return h.map((level, i) => {
    const dh = (inflow[i] - out[i]) / p.S;
    return level <= 0 && dh < 0 ? 0 : dh;
  });
}

/**
 * Advance levels h by dt seconds with inputs held (zero-order hold), in substeps of at most
 * `substep` seconds of classical RK4; returns the new levels (clamped to >= 0).
 */
function step(h, qa, qb, dt, substep = 0.25) {
  const n = Math.max(1, Math.ceil(dt / substep - 1e-9));
  const d = dt / n;
  let x = h.slice();
  const add = (a, b, c) => a.map((v, i) => v + c * b[i]);
  for (let k = 0; k < n; k++) {
    const k1 = derivatives(x, qa, qb);
    const k2 = derivatives(add(x, k1, d / 2), qa, qb);
    const k3 = derivatives(add(x, k2, d / 2), qa, qb);
    const k4 = derivatives(add(x, k3, d), qa, qb);
    x = x.map((v, i) => Math.max(v + (d / 6) * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]), 0));
  }
  return x;
}

module.exports = { PARAMETERS, START, derivatives, step };
