//! Just enough SPIR-V reflection to avoid writing facts twice: a compute shader's workgroup size
//! (used when dispatching), the member offsets of its structs (which `tests/layout.rs` compares
//! with the Rust `#[repr(C)]` mirrors) and the set/binding of its buffers. Instruction encoding per the SPIR-V specification §2.3.

use std::collections::HashMap;

const OP_NAME: u32 = 5;
const OP_MEMBER_NAME: u32 = 6;
const OP_EXECUTION_MODE: u32 = 16;
const OP_TYPE_RUNTIME_ARRAY: u32 = 29;
const OP_TYPE_POINTER: u32 = 32;
const OP_VARIABLE: u32 = 59;
const DECORATION_BINDING: u32 = 33;
const DECORATION_DESCRIPTOR_SET: u32 = 34;
const OP_DECORATE: u32 = 71;
const OP_MEMBER_DECORATE: u32 = 72;
const EXECUTION_MODE_LOCAL_SIZE: u32 = 17;
const DECORATION_ARRAY_STRIDE: u32 = 6;
const DECORATION_OFFSET: u32 = 35;

/// The reflected facts of one module.
#[derive(Debug, Default)]
pub struct Reflection {
    /// `LocalSize` of the (single) compute entry point.
    pub local_size: Option<[u32; 3]>,
    /// Struct name → (member name, byte offset), in declaration order. Structs with the same
    /// name declared under several layouts keep the first one that carries offsets.
    pub structs: HashMap<String, Vec<(String, u32)>>,
    /// Element struct name → `ArrayStride` of the runtime arrays (`T buf[]`) holding it.
    pub array_strides: HashMap<String, u32>,
    /// Block (struct type) name → (descriptor set, binding) of the variable declared with it.
    pub bindings: HashMap<String, (u32, u32)>,
}

fn string_at(words: &[u32]) -> String {
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// Reflects `words`; malformed input yields whatever was parsed before the damage.
pub fn reflect(words: &[u32]) -> Reflection {
    let mut names: HashMap<u32, String> = HashMap::new();
    let mut member_names: HashMap<(u32, u32), String> = HashMap::new();
    let mut offsets: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
    let mut strides: HashMap<u32, u32> = HashMap::new();
    let mut runtime_arrays: Vec<(u32, u32)> = Vec::new();
    let mut pointee: HashMap<u32, u32> = HashMap::new();
    let mut variables: Vec<(u32, u32)> = Vec::new();
    let mut sets: HashMap<u32, u32> = HashMap::new();
    let mut binding_of: HashMap<u32, u32> = HashMap::new();
    let mut out = Reflection::default();
    let mut i = 5;
    while i < words.len() {
        let count = (words[i] >> 16) as usize;
        let op = words[i] & 0xFFFF;
        if count == 0 || i + count > words.len() {
            break;
        }
        let args = &words[i + 1..i + count];
        match op {
            OP_NAME if !args.is_empty() => {
                names.insert(args[0], string_at(&args[1..]));
            }
            OP_MEMBER_NAME if args.len() >= 2 => {
                member_names.insert((args[0], args[1]), string_at(&args[2..]));
            }
            OP_EXECUTION_MODE if args.len() >= 5 && args[1] == EXECUTION_MODE_LOCAL_SIZE => {
                out.local_size = Some([args[2], args[3], args[4]]);
            }
            OP_MEMBER_DECORATE if args.len() >= 4 && args[2] == DECORATION_OFFSET => {
                offsets.entry(args[0]).or_default().push((args[1], args[3]));
            }
            OP_DECORATE if args.len() >= 3 && args[1] == DECORATION_ARRAY_STRIDE => {
                strides.insert(args[0], args[2]);
            }
            OP_DECORATE if args.len() >= 3 && args[1] == DECORATION_DESCRIPTOR_SET => {
                sets.insert(args[0], args[2]);
            }
            OP_DECORATE if args.len() >= 3 && args[1] == DECORATION_BINDING => {
                binding_of.insert(args[0], args[2]);
            }
            OP_TYPE_RUNTIME_ARRAY if args.len() >= 2 => runtime_arrays.push((args[0], args[1])),
            OP_TYPE_POINTER if args.len() >= 3 => {
                pointee.insert(args[0], args[2]);
            }
            OP_VARIABLE if args.len() >= 2 => variables.push((args[1], args[0])),
            _ => {}
        }
        i += count;
    }
    for (array, element) in runtime_arrays {
        if let (Some(name), Some(&stride)) = (names.get(&element), strides.get(&array)) {
            out.array_strides.insert(name.clone(), stride);
        }
    }
    for (variable, pointer) in variables {
        let block = pointee.get(&pointer).and_then(|t| names.get(t));
        if let (Some(block), Some(&set), Some(&binding)) =
            (block, sets.get(&variable), binding_of.get(&variable))
        {
            out.bindings.insert(block.clone(), (set, binding));
        }
    }
    let mut ids: Vec<_> = offsets.keys().copied().collect();
    ids.sort_unstable();
    for id in ids {
        let Some(name) = names.get(&id) else { continue };
        let mut members = offsets[&id].clone();
        members.sort_unstable();
        let members = members
            .into_iter()
            .map(|(m, off)| (member_names.get(&(id, m)).cloned().unwrap_or_default(), off))
            .collect();
        out.structs.entry(name.clone()).or_insert(members);
    }
    out
}
