//! Minimal firmware files for the flashing tests: an ELF32 little-endian ARM executable
//! with the program headers given (the layout of the ELF specification's file header and
//! program header table, written out field by field).

/// One program header: `p_type` (1 = PT_LOAD), physical and virtual address, the
/// segment's bytes in the file, and `p_memsz` (more than the data for a .bss-like tail).
#[derive(Debug, Clone)]
pub struct ProgramHeader {
    pub p_type: u32,
    pub paddr: u32,
    pub vaddr: u32,
    pub data: Vec<u8>,
    pub memsz: u32,
}

/// The ELF file with `headers`, their data placed after the header table in order.
pub fn elf(headers: &[ProgramHeader]) -> Vec<u8> {
    let phoff = 52u32;
    let data_start = phoff + 32 * headers.len() as u32;
    let mut out = vec![0u8; data_start as usize];
    out[..4].copy_from_slice(b"\x7fELF");
    out[4] = 1; // ELFCLASS32
    out[5] = 1; // ELFDATA2LSB
    out[6] = 1; // EV_CURRENT
    out[16..18].copy_from_slice(&2u16.to_le_bytes()); // ET_EXEC
    out[18..20].copy_from_slice(&40u16.to_le_bytes()); // EM_ARM
    out[20..24].copy_from_slice(&1u32.to_le_bytes()); // e_version
    out[28..32].copy_from_slice(&phoff.to_le_bytes());
    out[40..42].copy_from_slice(&52u16.to_le_bytes()); // e_ehsize
    out[42..44].copy_from_slice(&32u16.to_le_bytes()); // e_phentsize
    out[44..46].copy_from_slice(&(headers.len() as u16).to_le_bytes());
    let mut offset = data_start;
    for (i, h) in headers.iter().enumerate() {
        let at = phoff as usize + 32 * i;
        let words = [
            h.p_type,
            offset,
            h.vaddr,
            h.paddr,
            h.data.len() as u32,
            h.memsz,
            5, // PF_R | PF_X
            4, // alignment
        ];
        for (k, w) in words.iter().enumerate() {
            out[at + 4 * k..at + 4 * k + 4].copy_from_slice(&w.to_le_bytes());
        }
        offset += h.data.len() as u32;
    }
    for h in headers {
        out.extend_from_slice(&h.data);
    }
    out
}

/// An ELF with one loadable segment of `data` at `paddr` (= vaddr).
pub fn one_segment_elf(paddr: u32, data: &[u8]) -> Vec<u8> {
    elf(&[ProgramHeader {
        p_type: 1,
        paddr,
        vaddr: paddr,
        data: data.to_vec(),
        memsz: data.len() as u32,
    }])
}
