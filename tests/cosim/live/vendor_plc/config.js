"use strict";
/**
 * The vendor PLC's configuration: which case it plays (tags, units, data types, clock,
 * faults), read from a JSON file and the command line, checked before anything starts.
 *
 * {
 *   "port": 4841,                 listening port (the server binds 127.0.0.1 only)
 *   "speed": 250,                 speed-up K: one sample every Ts / K seconds
 *   "Ts": 25,                     sample time of the process [s]
 *   "duration": 120,              stop by itself after this many seconds [wall clock]
 *   "record": "plant.csv",        the PLC's own record (CSV)
 *   "frozen": true,               hold the process until a client first writes an input
 *   "namespace": "urn:acme:...",  the vendor's namespace URI
 *   "namespaces_before": 1,       namespaces registered before it (its index: 2 + this)
 *   "clock_offset": 0,            seconds added to every timestamp the PLC publishes
 *   "stamp_reads": false,         stamp every read with the read time (as open62541 does)
 *   "tags": {"h1": {"id": "s=PLC1.LT101.PV", "unit": "%", "type": "Float",
 *                   "span": [0, 2]}},          per signal, over the defaults below
 *   "faults": [{"kind": "freeze", "tag": "h1", "from": 20},
 *              {"kind": "value", "tag": "h1", "value": 1e30, "from": 10, "to": 15},
 *              {"kind": "delete", "tag": "qb", "at": 20}]
 * }
 *
 * Samples count the process's steps: sample k publishes the levels at time k Ts.
 */

const fs = require("fs");

/** The PLC's tags by the problem's signal (the vendor's names; SI spans of the process). */
const DEFAULT_TAGS = Object.freeze({
  h1: { id: "s=PLC1.LT101.PV", name: "LT101.PV", folder: "Levels", role: "output",
        unit: "m", type: "Double", span: [0, 2], description: "level of tank 1" },
  h2: { id: "i=1002", name: "LT102.PV", folder: "Levels", role: "output",
        unit: "m", type: "Double", span: [0, 2], description: "level of tank 2" },
  h3: { id: "s=PLC1.LT103.PV", name: "LT103.PV", folder: "Levels", role: "output",
        unit: "m", type: "Double", span: [0, 2], description: "level of tank 3" },
  h4: { id: "s=PLC1.LT104.PV", name: "LT104.PV", folder: "Levels", role: "output",
        unit: "m", type: "Double", span: [0, 2], description: "level of tank 4" },
  qa: { id: "s=PLC1.P101.OUT", name: "P101.OUT", folder: "Pumps", role: "input",
        unit: "m3/s", type: "Double", span: [0, 9.05e-4], description: "pump A flow" },
  qb: { id: "i=2002", name: "P102.OUT", folder: "Pumps", role: "input",
        unit: "m3/s", type: "Double", span: [0, 11.1e-4], description: "pump B flow" },
});

/** Units a tag may be in: UNECE code, display name, and the raw value of an SI value. */
const UNITS = Object.freeze({
  "m": { code: "MTR", display: "m", text: "metre", scale: 1 },
  "mm": { code: "MMT", display: "mm", text: "millimetre", scale: 1000 },
  "%": { code: "P1", display: "%", text: "percent of span", scale: null },
  "m3/s": { code: "MQS", display: "m³/s", text: "cubic metre per second", scale: 1 },
});

const TYPES = Object.freeze(["Float", "Double", "Int16"]);
const MAX_DURATION = 3600;
const KEYS = ["port", "speed", "Ts", "duration", "record", "frozen", "namespace",
              "namespaces_before", "clock_offset", "stamp_reads", "tags", "faults"];

class ConfigError extends Error {}

function fail(message) {
  throw new ConfigError(message);
}

function number(value, what, { min = -Infinity, integer = false } = {}) {
  if (typeof value !== "number" || !Number.isFinite(value) || value < min ||
      (integer && !Number.isInteger(value))) {
    fail(`${what}: expected ${integer ? "a whole number" : "a number"} >= ${min}, ` +
         `got ${JSON.stringify(value)}`);
  }
  return value;
}

/** Command-line options: --config FILE, then --port, --speed, --record, --duration. */
function parseArgs(argv) {
  const out = {};
  for (let i = 0; i < argv.length; i += 2) {
    const key = argv[i];
    const value = argv[i + 1];
    if (!key.startsWith("--") || value === undefined) {
      fail(`usage: node server.js --config FILE [--port N] [--speed K] [--record FILE] ` +
           `[--duration S] (got ${JSON.stringify(key)})`);
    }
    out[key.slice(2)] = value;
  }
  return out;
}

/** One tag: the defaults of its signal with the case's changes, checked. */
function tagOf(signal, given) {
  const tag = { ...DEFAULT_TAGS[signal], ...(given || {}), signal };
  if (!(tag.unit in UNITS)) fail(`tags.${signal}.unit: one of ${Object.keys(UNITS)}`);
  if (!TYPES.includes(tag.type)) fail(`tags.${signal}.type: one of ${TYPES}`);
  if (!/^(i=\d+|s=.+)$/.test(tag.id)) fail(`tags.${signal}.id: i=<number> or s=<string>`);
  if (!Array.isArray(tag.span) || tag.span.length !== 2 || !(tag.span[1] > tag.span[0])) {
    fail(`tags.${signal}.span: [low, high] with high > low (SI units)`);
  }
  return tag;
}

function checkFault(fault, i, tags) {
  const where = `faults[${i}]`;
  if (!(fault.tag in tags)) fail(`${where}.tag: one of ${Object.keys(tags)}`);
  if (fault.kind === "freeze") {
    number(fault.from, `${where}.from`, { min: 0, integer: true });
  } else if (fault.kind === "value") {
    number(fault.value, `${where}.value`);
    number(fault.from, `${where}.from`, { min: 0, integer: true });
    number(fault.to, `${where}.to`, { min: fault.from, integer: true });
  } else if (fault.kind === "delete") {
    number(fault.at, `${where}.at`, { min: 0, integer: true });
  } else {
    fail(`${where}.kind: freeze, value or delete`);
  }
  if (fault.kind !== "delete" && tags[fault.tag].role !== "output") {
    fail(`${where}: ${fault.kind} applies to a level (an output), not ${fault.tag}`);
  }
}

/** The case to play, from argv (``process.argv.slice(2)``); throws ConfigError. */
function load(argv) {
  const args = parseArgs(argv);
  let doc = {};
  if (args.config !== undefined) {
    try {
      doc = JSON.parse(fs.readFileSync(args.config, "utf8"));
    } catch (err) {
      fail(`--config ${args.config}: ${err.message}`);
    }
  }
  const unknown = Object.keys(doc).filter((k) => !KEYS.includes(k));
  if (unknown.length) fail(`unknown key ${unknown[0]} (known: ${KEYS.join(", ")})`);
  const cfg = {
    port: 4841, speed: 1, Ts: 25, duration: 120, record: null, frozen: false,
    namespace: "urn:acme-automation:plc1", namespaces_before: 1, clock_offset: 0,
    stamp_reads: false, ...doc,
  };
  for (const key of ["port", "speed", "duration"]) {
    if (args[key] !== undefined) cfg[key] = Number(args[key]);
  }
  if (args.record !== undefined) cfg.record = args.record;
  number(cfg.port, "port", { min: 1, integer: true });
  number(cfg.speed, "speed", { min: 1e-6 });
  number(cfg.Ts, "Ts", { min: 1e-6 });
  number(cfg.duration, "duration", { min: 0.1 });
  number(cfg.clock_offset, "clock_offset");
  number(cfg.namespaces_before, "namespaces_before", { min: 0, integer: true });
  cfg.duration = Math.min(cfg.duration, MAX_DURATION);
  const given = cfg.tags || {};
  const extra = Object.keys(given).filter((k) => !(k in DEFAULT_TAGS));
  if (extra.length) fail(`tags.${extra[0]}: not a tag (tags: ${Object.keys(DEFAULT_TAGS)})`);
  cfg.tags = Object.fromEntries(Object.keys(DEFAULT_TAGS).map((s) => [s, tagOf(s, given[s])]));
  cfg.faults = cfg.faults || [];
  cfg.faults.forEach((f, i) => checkFault(f, i, cfg.tags));
  return cfg;
}

/** The raw value a tag carries for the SI value v (its unit and data type). */
function toRaw(tag, v) {
  const unit = UNITS[tag.unit];
  const raw = unit.scale === null
    ? 100 * (v - tag.span[0]) / (tag.span[1] - tag.span[0]) : v * unit.scale;
  return cast(tag, raw);
}

/** The SI value of a raw value of the tag. */
function fromRaw(tag, raw) {
  const unit = UNITS[tag.unit];
  return unit.scale === null
    ? tag.span[0] + (raw / 100) * (tag.span[1] - tag.span[0]) : raw / unit.scale;
}

/** A number as the tag's data type holds it. */
function cast(tag, value) {
  if (tag.type === "Float") return Math.fround(value);
  if (tag.type === "Int16") return Math.min(Math.max(Math.round(value), -32768), 32767);
  return value;
}

/** The tag's EURange [raw units]. */
function rangeOf(tag) {
  return UNITS[tag.unit].scale === null ? [0, 100] : tag.span.map((v) => toRaw(tag, v));
}

module.exports = { ConfigError, DEFAULT_TAGS, UNITS, cast, fromRaw, load, rangeOf, toRaw };
