//! The raw reads from Blender's memory and why one was refused.

/// Why the memory was not read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReadError {
    /// The pointer is null.
    Null,
    /// The mesh does not have the number of vertices the caller expects (stale pointer or a
    /// mesh being edited).
    VertexCount { expected: usize, found: i64 },
    /// The pose does not have the number of channels the caller expects.
    ChannelCount { expected: usize, found: usize },
    /// The object is not an armature, or has no pose.
    NotAnArmature(&'static str),
    /// A count read from memory is out of any sane range: the layout does not fit this memory.
    Implausible(&'static str),
}

impl core::fmt::Display for ReadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ReadError::Null => write!(f, "the pointer is null"),
            ReadError::VertexCount { expected, found } => {
                write!(f, "the mesh in memory has {found} vertices, expected {expected}")
            }
            ReadError::ChannelCount { expected, found } => {
                write!(f, "the pose in memory has {found} channels, expected {expected}")
            }
            ReadError::NotAnArmature(why) => write!(f, "not an armature with a pose: {why}"),
            ReadError::Implausible(what) => write!(f, "implausible {what} in memory: the layout does not match"),
        }
    }
}

impl std::error::Error for ReadError {}

/// A value of type `T` at `address`, whatever its alignment.
///
/// # Safety
/// `address .. address + size_of::<T>()` must lie inside a live object, and `T` must be valid
/// for any bit pattern there (numbers, pointers as `usize`).
#[inline]
pub(crate) unsafe fn read<T: Copy>(address: usize) -> T {
    // SAFETY: the caller's guarantee.
    unsafe { core::ptr::read_unaligned(address as *const T) }
}

/// The bytes of a NUL-terminated name in a `char[size]` field.
///
/// # Safety
/// The field is `size` bytes inside a live struct.
pub(crate) unsafe fn name_bytes<'a>(address: usize, size: usize) -> &'a [u8] {
    // SAFETY: the caller's.
    let bytes = unsafe { core::slice::from_raw_parts(address as *const u8, size) };
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(size);
    &bytes[..end]
}

/// Asks the CPU for the cache line at `address` ahead of a read: only a hint, which never
/// faults and never changes what is read, whatever the address (a stale one too).
#[inline(always)]
pub(crate) fn prefetch(address: usize) {
    // SAFETY: SSE is part of every x86_64 CPU, and a prefetch reads nothing.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        core::arch::x86_64::_mm_prefetch::<{ core::arch::x86_64::_MM_HINT_T0 }>(address as *const i8)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}
