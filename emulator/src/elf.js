// Loads the loadable segments of a 32-bit little-endian ARM ELF into the RP2040's flash image.

const PT_LOAD = 1;
const FLASH_BASE = 0x10000000;

export class ElfError extends Error {}

/**
 * Copies every PT_LOAD segment whose load address (p_paddr) lies in flash into `flash`
 * (a Uint8Array mapped at 0x10000000). Returns the number of bytes copied.
 */
export function loadElfIntoFlash(bytes, flash) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (bytes.length < 52 || view.getUint32(0, false) !== 0x7f454c46) {
    throw new ElfError('not an ELF file');
  }
  if (bytes[4] !== 1 || bytes[5] !== 1) {
    throw new ElfError('not a 32-bit little-endian ELF');
  }
  if (view.getUint16(18, true) !== 40) {
    throw new ElfError('not an ARM ELF');
  }
  const phoff = view.getUint32(28, true);
  const phentsize = view.getUint16(42, true);
  const phnum = view.getUint16(44, true);
  if (phentsize < 32 || phoff + phnum * phentsize > bytes.length) {
    throw new ElfError('program headers out of range');
  }
  let copied = 0;
  for (let i = 0; i < phnum; i++) {
    const ph = phoff + i * phentsize;
    if (view.getUint32(ph, true) !== PT_LOAD) continue;
    const offset = view.getUint32(ph + 4, true);
    const paddr = view.getUint32(ph + 12, true);
    const filesz = view.getUint32(ph + 16, true);
    if (filesz === 0) continue;
    if (offset + filesz > bytes.length) {
      throw new ElfError(`segment ${i} extends past the end of the file`);
    }
    if (paddr < FLASH_BASE || paddr + filesz > FLASH_BASE + flash.length) {
      continue; // RAM-only segment (e.g. .bss): nothing to store in flash
    }
    flash.set(bytes.subarray(offset, offset + filesz), paddr - FLASH_BASE);
    copied += filesz;
  }
  if (copied === 0) {
    throw new ElfError('no loadable segment in flash');
  }
  return copied;
}
