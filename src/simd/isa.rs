//! Which instruction set the kernels run on, chosen at run time.
//!
//! [`Isa`] names the three tiers raypack compiles its kernels for. The best tier the CPU
//! has is detected once ([`Isa::detected`]); `RAYPACK_ISA=sse|avx2|avx512` lowers it for the
//! whole process ([`Isa::default_for_process`]), for tests and comparisons, and each
//! [`crate::Scene`] can be set to any supported tier ([`crate::Scene::set_isa`]).
//!
//! A kernel is an `IsaOp`: a small struct holding its arguments whose `run::<I>()` is
//! generic over the lane set `I` ([`IsaLanes`]) and `#[inline(always)]` all the way down.
//! `dispatch` instantiates it once per tier inside a `#[target_feature]` function (the
//! approach of Embree, and of the `pulp` and `multiversion` crates), so one kernel source
//! compiles to SSE2, AVX2 and AVX-512 code in one binary.

use super::{F32x4, F32x8, F32x16, Lanes, Transpose8};
use std::sync::OnceLock;

/// An instruction-set tier of the kernels, lowest first (`Baseline < Avx2 < Avx512`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// The build target's own SIMD: SSE2 on x86-64 (every x86-64 CPU), via the `wide` crate.
    Baseline,
    /// x86-64-v3: AVX2, FMA, BMI1/2, LZCNT, POPCNT (Intel Haswell, AMD Zen and later).
    Avx2,
    /// x86-64-v4: AVX-512 F, VL, DQ, BW, CD on top of AVX2 (Intel Skylake-SP, Ice Lake,
    /// Sapphire Rapids; AMD Zen 4 and later).
    Avx512,
}

/// An ISA name that raypack does not know, or a tier the CPU lacks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IsaError {
    /// Not one of the names [`Isa::parse`] accepts.
    #[error("unknown ISA `{0}`: expected sse, avx2 or avx512")]
    Unknown(String),
    /// The CPU does not have the tier's instructions.
    #[error("this CPU does not support {requested} (its best is {best})")]
    Unsupported {
        /// The tier asked for.
        requested: Isa,
        /// The best tier the CPU has.
        best: Isa,
    },
}

impl Isa {
    /// Every tier, lowest first.
    pub const ALL: [Isa; 3] = [Isa::Baseline, Isa::Avx2, Isa::Avx512];

    /// Short name: `sse2` (`portable` off x86-64), `avx2`, `avx512`.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline if cfg!(target_arch = "x86_64") => "sse2",
            Isa::Baseline => "portable",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// Parses `sse`, `sse2`, `baseline`, `avx2` or `avx512` (any case).
    pub fn parse(s: &str) -> Result<Isa, IsaError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "sse" | "sse2" | "baseline" | "portable" => Ok(Isa::Baseline),
            "avx2" => Ok(Isa::Avx2),
            "avx512" | "avx-512" => Ok(Isa::Avx512),
            _ => Err(IsaError::Unknown(s.to_string())),
        }
    }

    /// The best tier this CPU supports (detected once).
    pub fn detected() -> Isa {
        static BEST: OnceLock<Isa> = OnceLock::new();
        *BEST.get_or_init(detect)
    }

    /// True when the CPU has every instruction of this tier.
    pub fn is_supported(self) -> bool {
        self <= Isa::detected()
    }

    /// `self` if the CPU supports it, else the error naming the CPU's best.
    pub fn check(self) -> Result<Isa, IsaError> {
        if self.is_supported() {
            Ok(self)
        } else {
            Err(IsaError::Unsupported { requested: self, best: Isa::detected() })
        }
    }

    /// The tier asked for by the environment variable `RAYPACK_ISA`, if it is set (an
    /// unknown name, or a value that is not UTF-8 text, is an error; a tier above the CPU's
    /// is returned as asked, for the caller to report).
    pub fn from_env() -> Result<Option<Isa>, IsaError> {
        Isa::from_env_value(std::env::var_os("RAYPACK_ISA").as_deref())
    }

    /// [`Isa::from_env`] of the value `value` (`None`: unset).
    fn from_env_value(value: Option<&std::ffi::OsStr>) -> Result<Option<Isa>, IsaError> {
        match value.map(|v| v.to_str().ok_or(v)) {
            None => Ok(None),
            Some(Ok(s)) if s.trim().is_empty() => Ok(None),
            Some(Ok(s)) => Isa::parse(s).map(Some),
            // Shown with its bytes escaped: `"\xFF"`.
            Some(Err(bytes)) => Err(IsaError::Unknown(format!("{bytes:?}"))),
        }
    }

    /// `RAYPACK_ISA` checked, in the words every front end uses (the CLI prints them; the
    /// Python module raises the error as a `ValueError` and the warning as a `UserWarning`):
    /// `Err` for an unknown name or a value that is not UTF-8, `Ok(Some(warning))` for a
    /// tier this CPU lacks (its best is used instead), `Ok(None)` when it is unset or fine.
    pub fn env_report() -> Result<Option<String>, String> {
        Isa::env_report_for(std::env::var_os("RAYPACK_ISA").as_deref(), Isa::detected())
    }

    /// [`Isa::env_report`] of the value `value` on a CPU whose best tier is `best`.
    fn env_report_for(value: Option<&std::ffi::OsStr>, best: Isa) -> Result<Option<String>, String> {
        match Isa::from_env_value(value) {
            Err(e) => Err(format!("RAYPACK_ISA: {e}")),
            Ok(Some(isa)) if isa > best => Ok(Some(format!("RAYPACK_ISA={isa}: this CPU's best is {best}; using it"))),
            Ok(_) => Ok(None),
        }
    }

    /// The tier new scenes use: the CPU's best, lowered to `RAYPACK_ISA` when that names a
    /// lower tier (an unknown name or a higher tier leaves the best; the CLI reports both).
    /// Read once per process.
    pub fn default_for_process() -> Isa {
        static DEFAULT: OnceLock<Isa> = OnceLock::new();
        *DEFAULT.get_or_init(|| match Isa::from_env() {
            Ok(Some(isa)) => isa.min(Isa::detected()),
            _ => Isa::detected(),
        })
    }

    /// The tiers this process may run: every supported tier up to
    /// [`Isa::default_for_process`], lowest first. Tests run their kernel checks on each.
    pub fn available() -> impl Iterator<Item = Isa> {
        Isa::ALL.into_iter().filter(|&i| i <= Isa::default_for_process())
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Isa {
    type Err = IsaError;
    fn from_str(s: &str) -> Result<Isa, IsaError> {
        Isa::parse(s)
    }
}

#[cfg(target_arch = "x86_64")]
fn detect() -> Isa {
    use std::arch::is_x86_feature_detected as has;
    let v3 = has!("avx")
        && has!("avx2")
        && has!("fma")
        && has!("bmi1")
        && has!("bmi2")
        && has!("lzcnt")
        && has!("popcnt")
        && has!("f16c")
        && has!("movbe");
    let v4 = v3 && has!("avx512f") && has!("avx512vl") && has!("avx512dq") && has!("avx512bw") && has!("avx512cd");
    if v4 {
        Isa::Avx512
    } else if v3 {
        Isa::Avx2
    } else {
        Isa::Baseline
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn detect() -> Isa {
    Isa::Baseline
}

/// The lane types of one ISA tier, and the tier's tuning. Kernels are generic over it.
pub trait IsaLanes: Copy + Send + Sync + 'static {
    /// The tier.
    const ISA: Isa;
    /// 4 lanes (sphere blocks, `Tri4` blocks).
    type F4: Lanes;
    /// 8 lanes (BVH8 nodes, `Tri8` blocks, 8-ray packets).
    type F8: Transpose8;
    /// 16 lanes (16-ray packets).
    type F16: Lanes;
    /// The packet lanes of the stream queries ([`crate::Scene::intersect_stream`] and kin):
    /// `F16` or `F8`, whichever traces faster on this tier (see [`crate::bvh::queries`]).
    type Stream: Lanes;
}

/// The baseline tier's lanes (`wide`'s types). Also usable directly: it needs no CPU check.
#[derive(Clone, Copy, Debug)]
pub struct Baseline;

impl IsaLanes for Baseline {
    const ISA: Isa = Isa::Baseline;
    type F4 = F32x4;
    type F8 = F32x8;
    type F16 = F32x16;
    type Stream = F32x16;
}

/// The AVX2 tier's lanes.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2;

#[cfg(target_arch = "x86_64")]
impl IsaLanes for Avx2 {
    const ISA: Isa = Isa::Avx2;
    type F4 = F32x4;
    type F8 = super::x86::M256;
    type F16 = super::x86::Pair<super::x86::M256>;
    type Stream = super::x86::Pair<super::x86::M256>;
}

/// The AVX-512 tier's lanes.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx512;

#[cfg(target_arch = "x86_64")]
impl IsaLanes for Avx512 {
    const ISA: Isa = Isa::Avx512;
    type F4 = F32x4;
    type F8 = super::x86::M256;
    type F16 = super::x86::M512;
    type Stream = super::x86::M512;
}

/// A kernel invocation, run with the lanes of one ISA tier. `run` and everything it calls
/// must be `#[inline(always)]`, so that the whole kernel compiles inside [`dispatch`]'s
/// `#[target_feature]` function for that tier.
pub(crate) trait IsaOp {
    /// What the kernel returns.
    type Output;
    /// The kernel on the lanes of `I`.
    fn run<I: IsaLanes>(self) -> Self::Output;
}

/// Runs `op` on `isa`'s kernels, or on the best tier the CPU has when `isa` is above it.
#[inline]
pub(crate) fn dispatch<O: IsaOp>(isa: Isa, op: O) -> O::Output {
    #[cfg(target_arch = "x86_64")]
    {
        match isa.min(Isa::detected()) {
            Isa::Baseline => run_baseline(op),
            // SAFETY: the tier is at most the detected one, so the CPU has its features.
            Isa::Avx2 => unsafe { run_avx2(op) },
            // SAFETY: as above.
            Isa::Avx512 => unsafe { run_avx512(op) },
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = isa;
        op.run::<Baseline>()
    }
}

/// `op` compiled for the baseline tier, in a function of its own like the other tiers.
///
/// Inlined into [`dispatch`] instead, the baseline kernel gave `dispatch` its stack frame (a
/// single-ray kernel's is about 10 KB: the traversal stack and spilled constants, probed page
/// by page), which every call then set up even when it went on to the AVX2 or AVX-512 code;
/// where `dispatch` itself was not inlined (the `raypack` binary's thin-LTO build), that cost
/// `Scene::intersect1` much of its speed (PERFORMANCE.md, "Smaller measured choices").
#[inline(never)]
fn run_baseline<O: IsaOp>(op: O) -> O::Output {
    op.run::<Baseline>()
}

/// `op` compiled for x86-64-v3.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt,f16c,movbe,sse3,ssse3,sse4.1,sse4.2")]
unsafe fn run_avx2<O: IsaOp>(op: O) -> O::Output {
    op.run::<Avx2>()
}

/// `op` compiled for x86-64-v4.
#[cfg(target_arch = "x86_64")]
#[target_feature(
    enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt,f16c,movbe,sse3,ssse3,sse4.1,sse4.2,avx512f,avx512vl,avx512dq,avx512bw,avx512cd"
)]
unsafe fn run_avx512<O: IsaOp>(op: O) -> O::Output {
    op.run::<Avx512>()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lane checks of `simd::check_lanes` and `simd::check_transpose8` on every tier the CPU
    /// has.
    struct CheckLanes;
    impl IsaOp for CheckLanes {
        type Output = Isa;
        #[inline(always)]
        fn run<I: IsaLanes>(self) -> Isa {
            crate::simd::check_lanes::<I::F4>();
            crate::simd::check_lanes::<I::F8>();
            crate::simd::check_lanes::<I::F16>();
            crate::simd::check_transpose8::<I::F8>();
            I::ISA
        }
    }

    #[test]
    fn lanes_of_every_supported_tier() {
        for isa in Isa::available() {
            assert_eq!(dispatch(isa, CheckLanes), isa);
        }
    }

    #[test]
    fn names_parse_and_order() {
        for isa in Isa::ALL {
            assert_eq!(Isa::parse(isa.name()), Ok(isa));
        }
        assert_eq!(Isa::parse("SSE"), Ok(Isa::Baseline));
        assert!(matches!(Isa::parse("avx"), Err(IsaError::Unknown(_))));
        assert!(Isa::Baseline < Isa::Avx2 && Isa::Avx2 < Isa::Avx512);
        assert!(Isa::Baseline.is_supported());
        assert!(Isa::available().all(Isa::is_supported));
        assert_eq!(Isa::detected().check(), Ok(Isa::detected()));
    }

    #[test]
    fn the_environment_is_reported_in_the_same_words_everywhere() {
        use std::ffi::OsStr;
        let report = |v: Option<&OsStr>, best| Isa::env_report_for(v, best);
        assert_eq!(report(None, Isa::Avx2), Ok(None));
        assert_eq!(report(Some(OsStr::new(" ")), Isa::Avx2), Ok(None));
        assert_eq!(report(Some(OsStr::new("sse")), Isa::Avx2), Ok(None));
        assert_eq!(
            report(Some(OsStr::new("avx512")), Isa::Avx2),
            Ok(Some("RAYPACK_ISA=avx512: this CPU's best is avx2; using it".into()))
        );
        assert_eq!(
            report(Some(OsStr::new("fast")), Isa::Avx512),
            Err("RAYPACK_ISA: unknown ISA `fast`: expected sse, avx2 or avx512".into())
        );
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStrExt;
            assert_eq!(
                report(Some(OsStr::from_bytes(b"avx\xff")), Isa::Avx512),
                Err("RAYPACK_ISA: unknown ISA `\"avx\\xFF\"`: expected sse, avx2 or avx512".into())
            );
        }
    }
}
