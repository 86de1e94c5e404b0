// The USB host side of the emulated cable: enumerates the device behind rp2040js's USB
// controller (device mode), opens its CDC-ACM interface the way a Linux host does
// (SET_LINE_CODING, then SET_CONTROL_LINE_STATE with DTR|RTS addressed to the communication
// interface), and moves bulk data both ways.
//
// It also applies the silicon behaviour of OUT buffers (see patchOutBuffers): an armed OUT
// buffer keeps its AVAILABLE bit until a packet arrives.

const EP0_IN_BUFFER_CONTROL = 0x80;
const EP15_OUT_BUFFER_CONTROL = 0xfc;
const EP_CTRL_DOUBLE_BUF = 1 << 30;
const BUF_AVAILABLE = 1 << 10;
const BUF_FULL = 1 << 15;
const BUF_LEN_MASK = 0x3ff;

const DESC_DEVICE = 1;
const DESC_CONFIGURATION = 2;
const DESC_STRING = 3;
const DESC_INTERFACE = 4;
const DESC_ENDPOINT = 5;
const CLASS_CDC = 2;
const CLASS_CDC_DATA = 10;

// Host processing time between two control stages or two bulk packets.
const HOST_TURNAROUND_NS = 10_000;

function setup(bmRequestType, bRequest, wValue, wIndex, wLength) {
  return new Uint8Array([
    bmRequestType,
    bRequest,
    wValue & 0xff,
    wValue >> 8,
    wIndex & 0xff,
    wIndex >> 8,
    wLength & 0xff,
    wLength >> 8,
  ]);
}

/** Parses a configuration descriptor set: CDC interfaces and bulk endpoints. */
export function parseConfiguration(desc) {
  const result = { commInterface: -1, bulkIn: -1, bulkOut: -1, interfaces: [] };
  let inData = false;
  for (let i = 0; i + 2 <= desc.length; ) {
    const len = desc[i];
    if (len < 2 || i + len > desc.length) break;
    const type = desc[i + 1];
    if (type === DESC_INTERFACE && len >= 9) {
      const number = desc[i + 2];
      const cls = desc[i + 5];
      result.interfaces.push({ number, cls, subclass: desc[i + 6], protocol: desc[i + 7] });
      if (cls === CLASS_CDC && result.commInterface < 0) result.commInterface = number;
      inData = cls === CLASS_CDC_DATA;
    }
    if (type === DESC_ENDPOINT && len >= 7 && inData && (desc[i + 3] & 3) === 2) {
      const address = desc[i + 2];
      if (address & 0x80) result.bulkIn = address & 0x0f;
      else result.bulkOut = address & 0x0f;
    }
    i += len;
  }
  return result;
}

export class UsbHost {
  /**
   * @param rp the RP2040
   * @param onData called with every bulk IN packet (Uint8Array) of the CDC data interface
   */
  constructor(rp, onData) {
    this.rp = rp;
    this.usb = rp.usbCtrl;
    this.onData = onData;
    this.outArmed = new Map(); // endpoint -> armed length
    this.outFifo = []; // pending host -> device bytes (arrays of numbers)
    this.outFifoBytes = 0;
    this.bulkScheduled = false;
    this.control = null; // the control transfer in progress
    this.queue = []; // control transfers still to run
    this.device = null; // { vid, pid, serial, config }
    this.configured = false;
    this.dtr = false;
    this.stats = { setupPackets: 0, bulkOutPackets: 0, bulkInPackets: 0, unexpectedEp0: 0 };
    this.patchOutBuffers();
    this.usb.onUSBEnabled = () => this.usb.resetDevice();
    this.usb.onResetReceived = () => this.enumerate();
    this.usb.onEndpointWrite = (ep, buffer) => this.endpointWrite(ep, buffer);
    this.usb.onEndpointRead = () => {};
  }

  defer(fn, ns = HOST_TURNAROUND_NS) {
    const alarm = this.rp.clock.createAlarm(fn);
    alarm.schedule(ns);
  }

  // rp2040js clears AVAILABLE as soon as firmware arms an OUT buffer; silicon keeps it set
  // until a packet has been received into the buffer, and embassy-rp reads a cleared
  // AVAILABLE as "packet received". Single-buffered OUT arms are taken over here.
  patchOutBuffers() {
    const usb = this.usb;
    const original = usb.DPRAMUpdated.bind(usb);
    usb.DPRAMUpdated = (offset, value) => {
      const isOutControl =
        !usb.hostMode &&
        offset >= EP0_IN_BUFFER_CONTROL &&
        offset <= EP15_OUT_BUFFER_CONTROL &&
        (offset & 4) !== 0 &&
        (offset & 3) === 0;
      if (isOutControl) {
        const ep = (offset - EP0_IN_BUFFER_CONTROL) >> 3;
        const doubleBuffered =
          ep !== 0 && (usb.readEndpointControlReg(ep, true) & EP_CTRL_DOUBLE_BUF) !== 0;
        if (!doubleBuffered) {
          if (value & BUF_AVAILABLE) {
            this.outArmed.set(ep, value & BUF_LEN_MASK);
            this.onOutArmed(ep);
          } else {
            this.outArmed.delete(ep);
          }
          return;
        }
      }
      original(offset, value);
    };
  }

  /**
   * Completes an armed OUT buffer with `bytes` (as the SIE does when a packet arrives).
   * Returns the number of bytes stored, or -1 if the buffer was not armed.
   */
  completeOut(ep, bytes) {
    const view = this.rp.usbDPRAMView;
    const controlOffset = EP0_IN_BUFFER_CONTROL + ep * 8 + 4;
    let control = view.getUint32(controlOffset, true);
    if (!(control & BUF_AVAILABLE) || !this.outArmed.has(ep)) return -1;
    const n = Math.min(bytes.length, control & BUF_LEN_MASK);
    const bufferOffset = this.usb.getEndpointBufferOffset(ep, true);
    this.rp.usbDPRAM.set(bytes.subarray(0, n), bufferOffset);
    control = (control & ~(BUF_LEN_MASK | BUF_AVAILABLE)) | BUF_FULL | n;
    view.setUint32(controlOffset, control, true);
    this.outArmed.delete(ep);
    this.usb.indicateBufferReady(ep, true);
    return n;
  }

  // ---- enumeration (control transfers on EP0) ----

  enumerate() {
    this.configured = false;
    this.dtr = false;
    this.device = null;
    this.control = null;
    this.queue = [
      { setup: setup(0x80, 6, DESC_DEVICE << 8, 0, 64), done: (d) => this.gotDevice(d) },
      { setup: setup(0x00, 5, 1, 0, 0) },
      { setup: setup(0x80, 6, DESC_CONFIGURATION << 8, 0, 9), done: (d) => this.gotConfigHead(d) },
    ];
    this.next();
  }

  gotDevice(d) {
    if (d.length < 18) return;
    this.device = {
      vid: d[8] | (d[9] << 8),
      pid: d[10] | (d[11] << 8),
      iSerial: d[16],
      serial: null,
      config: null,
    };
  }

  gotConfigHead(d) {
    if (d.length < 4) return;
    const total = d[2] | (d[3] << 8);
    this.queue.push({
      setup: setup(0x80, 6, DESC_CONFIGURATION << 8, 0, total),
      done: (full) => this.gotConfig(full),
    });
  }

  gotConfig(desc) {
    const config = parseConfiguration(desc);
    if (this.device) this.device.config = config;
    if (this.device && this.device.iSerial) {
      this.queue.push({
        setup: setup(0x80, 6, (DESC_STRING << 8) | this.device.iSerial, 0x0409, 255),
        done: (s) => {
          let text = '';
          for (let i = 2; i + 1 < s.length; i += 2) text += String.fromCharCode(s[i] | (s[i + 1] << 8));
          this.device.serial = text;
        },
      });
    }
    this.queue.push({ setup: setup(0x00, 9, 1, 0, 0), done: () => (this.configured = true) });
    if (config.commInterface >= 0 && config.bulkIn >= 0 && config.bulkOut >= 0) {
      const iface = config.commInterface;
      // 115200 baud, 1 stop bit, no parity, 8 data bits (ignored by the firmware).
      const coding = new Uint8Array([0x00, 0xc2, 0x01, 0x00, 0, 0, 8]);
      this.queue.push({ setup: setup(0x21, 0x20, 0, iface, 7), dataOut: coding });
      this.queue.push({
        setup: setup(0x21, 0x22, 0x0003, iface, 0),
        done: () => {
          this.dtr = true;
          this.kickBulk();
        },
      });
    }
  }

  next() {
    if (this.control || this.queue.length === 0) return;
    const transfer = this.queue.shift();
    const wLength = transfer.setup[6] | (transfer.setup[7] << 8);
    const deviceToHost = (transfer.setup[0] & 0x80) !== 0;
    this.control = {
      ...transfer,
      wLength,
      deviceToHost,
      received: [],
      stage: deviceToHost && wLength > 0 ? 'in' : transfer.dataOut ? 'out' : 'status-in',
    };
    this.defer(() => {
      this.stats.setupPackets++;
      this.usb.sendSetupPacket(transfer.setup);
    });
  }

  finishControl() {
    const c = this.control;
    this.control = null;
    if (c && c.done) c.done(new Uint8Array(c.received));
    this.defer(() => this.next());
  }

  onOutArmed(ep) {
    if (ep !== 0) {
      this.kickBulk();
      return;
    }
    const c = this.control;
    if (!c) return;
    if (c.stage === 'out') {
      const data = c.dataOut;
      c.stage = 'status-in';
      this.defer(() => this.completeOut(0, data));
    } else if (c.stage === 'status-out') {
      this.defer(() => {
        if (this.completeOut(0, new Uint8Array(0)) >= 0 && this.control === c) this.finishControl();
      });
    }
  }

  endpointWrite(ep, buffer) {
    if (ep === 0) {
      const c = this.control;
      if (!c) {
        this.stats.unexpectedEp0++;
        return;
      }
      if (c.stage === 'in') {
        for (const b of buffer) c.received.push(b);
        if (buffer.length < 64 || c.received.length >= c.wLength) {
          c.stage = 'status-out';
          if (this.outArmed.has(0)) this.onOutArmed(0);
        }
      } else if (c.stage === 'status-in' && buffer.length === 0) {
        this.finishControl();
      }
      return;
    }
    const config = this.device && this.device.config;
    if (config && ep === config.bulkIn) {
      this.stats.bulkInPackets++;
      this.onData(buffer);
    }
  }

  // ---- bulk OUT: host -> device ----

  /** Queues bytes the host writes to the serial port. */
  write(bytes) {
    if (bytes.length === 0) return;
    for (const b of bytes) this.outFifo.push(b);
    this.outFifoBytes = this.outFifo.length;
    this.kickBulk();
  }

  kickBulk() {
    const config = this.device && this.device.config;
    if (!this.dtr || !config || this.bulkScheduled || this.outFifo.length === 0) return;
    if (!this.outArmed.has(config.bulkOut)) return;
    this.bulkScheduled = true;
    this.defer(() => {
      this.bulkScheduled = false;
      const armed = this.outArmed.get(config.bulkOut);
      if (armed === undefined || this.outFifo.length === 0) return;
      const n = Math.min(64, armed, this.outFifo.length);
      const packet = new Uint8Array(this.outFifo.splice(0, n));
      this.completeOut(config.bulkOut, packet);
      this.stats.bulkOutPackets++;
      this.kickBulk();
    });
  }
}
