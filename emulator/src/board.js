// The bench board around the emulated RP2040: what the plant (hil-sim) drives into the pins
// and what the firmware drives out of them. Pinout as in firmware/rp2040/src/board.rs:
// ADC0 (GP26) proximity, ADC1 (GP27) manometer, GP2/GP3 HX711 DOUT/PD_SCK, GP4 pump PWM,
// GP5 LED PWM, GP6 vent (high = closed), GP10/11/12 stepper STEP/DIR/EN (EN active low).

const HIGH = 1; // GPIOPinState.High
const PIN_HX711_DOUT = 2;
const PIN_HX711_SCK = 3;
const PIN_PUMP = 4;
const PIN_LED = 5;
const PIN_VENT = 6;
const PIN_STEP = 10;
const PIN_DIR = 11;
const PIN_EN = 12;
const ADC_VREF_V = 3.3;
const TICK_PERIOD_NS = 500_000;

/** Seeded normal deviates (xorshift64* and Box-Muller), reproducible for a seed. */
export class Rng {
  constructor(seed) {
    this.state = BigInt.asUintN(64, BigInt(seed) * 0x9e3779b97f4a7c15n + 0x2545f4914f6cdd1dn) || 1n;
    this.spare = null;
  }
  nextU32() {
    let x = this.state;
    x ^= x >> 12n;
    x ^= BigInt.asUintN(64, x << 25n);
    x ^= x >> 27n;
    this.state = x;
    return Number(BigInt.asUintN(64, x * 0x2545f4914f6cdd1dn) >> 32n);
  }
  uniform() {
    return (this.nextU32() + 0.5) / 4294967296;
  }
  normal(sigma) {
    if (this.spare !== null) {
      const s = this.spare;
      this.spare = null;
      return s * sigma;
    }
    const r = Math.sqrt(-2 * Math.log(this.uniform()));
    const phi = 2 * Math.PI * this.uniform();
    this.spare = r * Math.sin(phi);
    return r * Math.cos(phi) * sigma;
  }
}

/** Time-weighted high fraction of an output pin over a window. */
class DutyMeter {
  constructor(pin, now) {
    this.high = pin.value === HIGH;
    this.since = now;
    this.highNs = 0;
    this.risingEdges = 0;
    this.lastRise = null;
    this.minPeriodNs = Infinity;
    this.periods = []; // rise-to-rise intervals below 1 ms (longer ones span a 0 % duty)
  }
  change(high, now) {
    if (high === this.high) return;
    if (this.high) this.highNs += now - this.since;
    if (high) {
      this.risingEdges++;
      if (this.lastRise !== null) {
        const period = now - this.lastRise;
        this.minPeriodNs = Math.min(this.minPeriodNs, period);
        if (period < 1e6 && this.periods.length < 1e6) this.periods.push(period);
      }
      this.lastRise = now;
    }
    this.high = high;
    this.since = now;
  }
  /**
   * Rise-to-rise intervals that are not a whole number of PWM periods (the shortest
   * interval seen), within one 8 ns clock: a counter that was disturbed. Intervals that
   * span cycles at 0 % duty are whole numbers of periods.
   */
  offGridPeriods() {
    const p = this.minPeriodNs;
    if (!Number.isFinite(p)) return 0;
    let n = 0;
    for (const period of this.periods) {
      const rest = period - Math.round(period / p) * p;
      if (Math.abs(rest) > 8) n++;
    }
    return n;
  }

  take(windowStart, now) {
    if (this.high) this.highNs += now - this.since;
    this.since = now;
    const span = now - windowStart;
    const duty = span > 0 ? Math.min(1, this.highNs / span) : this.high ? 1 : 0;
    this.highNs = 0;
    return duty;
  }
}

export class Board {
  /**
   * @param rp the chip
   * @param inputs live plant values: { proximityV, manometerV, loadCounts, adcNoiseLsb,
   *   hx711PeriodNs }, updated by the caller between runs
   * @param rng noise source of the ADC conversions
   */
  constructor(rp, watchdog, inputs, rng) {
    this.rp = rp;
    this.inputs = inputs;
    this.rng = rng;
    const now = rp.clock.nanos;
    this.windowStart = now;
    this.pump = new DutyMeter(rp.gpio[PIN_PUMP], now);
    this.led = new DutyMeter(rp.gpio[PIN_LED], now);
    this.steps = 0;
    this.stepsTotal = 0;
    this.stepsWhileDisabled = 0;
    this.hx711 = { ready: false, bit: 0, value: 0, conversions: 0, reads: 0 };
    this.tick = { inTick: false, startNs: 0, longestNs: 0, count: 0, phases: [] };
    this.adcConversions = 0;

    rp.gpio[PIN_PUMP].addListener((v) => this.pump.change(v === HIGH, rp.clock.nanos));
    rp.gpio[PIN_LED].addListener((v) => this.led.change(v === HIGH, rp.clock.nanos));
    rp.gpio[PIN_STEP].addListener((v, old) => {
      if (v === HIGH && old !== HIGH) this.stepEdge();
    });
    rp.gpio[PIN_HX711_SCK].addListener((v, old) => {
      if (v === HIGH && old !== HIGH) this.hx711Clock();
    });
    // DOUT idles high (pull-up, and the HX711 drives it high while converting).
    rp.gpio[PIN_HX711_DOUT].setInputValue(true);
    const conversion = rp.clock.createAlarm(() => {
      this.hx711Conversion();
      conversion.schedule(this.inputs.hx711PeriodNs);
    });
    conversion.schedule(this.inputs.hx711PeriodNs * 0.25);

    const adc = rp.adc;
    const startConversion = adc.onADCRead;
    adc.onADCRead = (channel) => {
      if (!this.tick.inTick) {
        // The control tick starts with its ADC burst ...
        this.tick.inTick = true;
        this.tick.startNs = rp.clock.nanos;
        if (this.tick.phases.length < 1e6) this.tick.phases.push(rp.clock.nanos % TICK_PERIOD_NS);
      }
      this.adcConversions++;
      adc.channelValues[channel] = this.adcCode(channel);
      startConversion(channel);
    };
    const watchdogWrite = watchdog.writeUint32.bind(watchdog);
    watchdog.writeUint32 = (offset, value) => {
      // ... and ends with the watchdog feed (LOAD).
      if (offset === 0x04 && this.tick.inTick) {
        const duration = rp.clock.nanos - this.tick.startNs;
        this.tick.longestNs = Math.max(this.tick.longestNs, duration);
        this.tick.count++;
        this.tick.inTick = false;
      }
      watchdogWrite(offset, value);
    };
  }

  adcCode(channel) {
    const v = channel === 0 ? this.inputs.proximityV : channel === 1 ? this.inputs.manometerV : 0;
    const ideal = (v / ADC_VREF_V) * 4096;
    const code = Math.round(ideal + this.rng.normal(this.inputs.adcNoiseLsb));
    return Math.max(0, Math.min(4095, code));
  }

  stepEdge() {
    const enabled = this.rp.gpio[PIN_EN].value !== HIGH; // active low
    if (!enabled) {
      this.stepsWhileDisabled++;
      return;
    }
    const dir = this.rp.gpio[PIN_DIR].value === HIGH ? 1 : -1;
    this.steps += dir;
    this.stepsTotal += dir;
  }

  hx711Conversion() {
    const h = this.hx711;
    if (h.bit > 0) return; // being read out: the chip finishes the transfer first
    const counts = Math.max(-(2 ** 23) + 1, Math.min(2 ** 23 - 1, Math.round(this.inputs.loadCounts)));
    h.value = counts & 0xffffff;
    h.ready = true;
    h.conversions++;
    this.rp.gpio[PIN_HX711_DOUT].setInputValue(false);
  }

  hx711Clock() {
    const h = this.hx711;
    const dout = this.rp.gpio[PIN_HX711_DOUT];
    if (!h.ready) return;
    if (h.bit < 24) {
      dout.setInputValue(((h.value >> (23 - h.bit)) & 1) === 1);
      h.bit++;
    } else {
      // 25th pulse: channel A, gain 128 next; DOUT high until the next conversion.
      h.ready = false;
      h.bit = 0;
      h.reads++;
      dout.setInputValue(true);
    }
  }

  /**
   * Longest delay of a control tick's start (its first ADC conversion) behind its place on
   * the 500 µs grid, whose phase is taken as the earliest start seen (so the figure is
   * relative to the quickest wake-up, a few µs after the deadline).
   */
  maxTickLatencyNs() {
    const phases = this.tick.phases;
    if (phases.length === 0) return null;
    // The grid phase: the start that most ticks follow closely is the smallest residue
    // after rotating the residues so that the largest gap between them wraps around.
    const sorted = Float64Array.from(phases).sort();
    let gapAt = 0;
    let gap = sorted[0] + TICK_PERIOD_NS - sorted[sorted.length - 1];
    for (let i = 1; i < sorted.length; i++) {
      if (sorted[i] - sorted[i - 1] > gap) {
        gap = sorted[i] - sorted[i - 1];
        gapAt = i;
      }
    }
    const phase = sorted[gapAt];
    let worst = 0;
    for (const r of phases) worst = Math.max(worst, (r - phase + TICK_PERIOD_NS) % TICK_PERIOD_NS);
    return worst;
  }

  /** Outputs averaged over the window since the last call. */
  takeOutputs() {
    const now = this.rp.clock.nanos;
    const out = {
      pump: this.pump.take(this.windowStart, now),
      led: this.led.take(this.windowStart, now),
      ventOpen: this.rp.gpio[PIN_VENT].value !== HIGH,
      steps: this.steps,
      stepperEnabled: this.rp.gpio[PIN_EN].value !== HIGH,
    };
    this.steps = 0;
    this.windowStart = now;
    return out;
  }
}
