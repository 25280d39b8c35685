//! Eight lanes of `f32`, one path in each: the type every lane kernel computes in.
//!
//! Why plain arrays and loops rather than intrinsics: the compiler turns each loop into one
//! vector instruction at whatever width the backend's target features allow (two SSE2
//! registers, one AVX2 register, half an AVX-512 one), and every operation here is an IEEE
//! basic operation (add, subtract, multiply, divide, square root, compare), which rounds the
//! same on every instruction set. Rust never fuses a multiply and an add unless asked to, so
//! no backend can contract `a * b + c` into an FMA and change the bits.
//!
//! `min` and `max` are written as comparisons, so their result for a NaN operand is defined by
//! the operand order (the second operand), not by the instruction set's convention.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// Paths per lane group.
pub const LANES: usize = 8;

/// Eight `f32`s, one per lane.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct F8(pub [f32; LANES]);

/// Eight lane conditions, each all ones or all zeros, as SIMD compares make them (a `[bool; 8]`
/// made every select and branch convert between bytes and masks: the packet traversal ran
/// 1.3× slower).
#[derive(Clone, Copy, PartialEq, Eq)]
#[repr(C, align(32))]
pub struct M8([u32; LANES]);

impl F8 {
    /// The same value in every lane.
    #[inline(always)]
    pub fn splat(x: f32) -> F8 {
        F8([x; LANES])
    }

    /// Lane `i` is `f(i)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f32) -> F8 {
        F8(std::array::from_fn(f))
    }

    /// Lanes `start..start + 8` of `v` (which must hold them).
    #[inline(always)]
    pub fn load(v: &[f32], start: usize) -> F8 {
        let mut a = [0.0; LANES];
        a.copy_from_slice(&v[start..start + LANES]);
        F8(a)
    }

    /// Writes the lanes to `v[start..start + 8]`.
    #[inline(always)]
    pub fn store(self, v: &mut [f32], start: usize) {
        v[start..start + LANES].copy_from_slice(&self.0);
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        F8(self.0.map(f))
    }

    #[inline(always)]
    fn zip(self, o: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        F8(std::array::from_fn(|i| f(self.0[i], o.0[i])))
    }

    #[inline(always)]
    fn cmp(self, o: F8, f: impl Fn(f32, f32) -> bool) -> M8 {
        M8::from_fn(|i| f(self.0[i], o.0[i]))
    }

    /// Correctly rounded square root.
    #[inline(always)]
    pub fn sqrt(self) -> F8 {
        self.map(f32::sqrt)
    }

    /// Absolute value (clears the sign bit).
    #[inline(always)]
    pub fn abs(self) -> F8 {
        self.map(f32::abs)
    }

    /// `self` if it is below `o`, else `o` (so `o` where either is NaN).
    #[inline(always)]
    pub fn min(self, o: F8) -> F8 {
        self.zip(o, |a, b| if a < b { a } else { b })
    }

    /// `self` if it is above `o`, else `o` (so `o` where either is NaN).
    #[inline(always)]
    pub fn max(self, o: F8) -> F8 {
        self.zip(o, |a, b| if a > b { a } else { b })
    }

    /// The least lane, folded from lane 0 up as [`F8::min`] does.
    #[inline(always)]
    pub fn reduce_min(self) -> f32 {
        self.0
            .into_iter()
            .fold(f32::INFINITY, |m, x| if x < m { x } else { m })
    }

    /// 1 with the sign of each lane (of -0.0 too).
    #[inline(always)]
    pub fn sign_one(self) -> F8 {
        self.map(|x| 1.0f32.copysign(x))
    }

    /// Lane-wise `<`.
    #[inline(always)]
    pub fn lt(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a < b)
    }

    /// Lane-wise `<=`.
    #[inline(always)]
    pub fn le(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a <= b)
    }

    /// Lane-wise `>`.
    #[inline(always)]
    pub fn gt(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a > b)
    }

    /// Lane-wise `>=`.
    #[inline(always)]
    pub fn ge(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a >= b)
    }

    /// Lane-wise `==`.
    #[inline(always)]
    pub fn eq(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a == b)
    }
}

impl M8 {
    /// Every lane `b`.
    #[inline(always)]
    pub fn splat(b: bool) -> M8 {
        M8::from_fn(|_| b)
    }

    /// Lane i holds where `f(i)`.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> bool) -> M8 {
        M8(std::array::from_fn(|i| if f(i) { u32::MAX } else { 0 }))
    }

    /// Whether lane `i` holds.
    #[inline(always)]
    pub fn get(self, i: usize) -> bool {
        self.0[i] != 0
    }

    /// Sets lane `i`.
    #[inline(always)]
    pub fn set(&mut self, i: usize, b: bool) {
        self.0[i] = if b { u32::MAX } else { 0 };
    }

    /// The lanes as booleans.
    #[inline(always)]
    pub fn to_bools(self) -> [bool; LANES] {
        self.0.map(|m| m != 0)
    }

    /// `a` in the lanes where the condition holds, `b` elsewhere (a bitwise blend).
    #[inline(always)]
    pub fn select(self, a: F8, b: F8) -> F8 {
        F8(std::array::from_fn(|i| {
            f32::from_bits((self.0[i] & a.0[i].to_bits()) | (!self.0[i] & b.0[i].to_bits()))
        }))
    }

    /// Whether any lane holds.
    #[inline(always)]
    pub fn any(self) -> bool {
        self.0.iter().fold(0, |acc, &m| acc | m) != 0
    }
}

impl std::fmt::Debug for M8 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.to_bools().fmt(f)
    }
}

macro_rules! binary {
    ($trait:ident, $f:ident, $op:tt) => {
        impl $trait for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl $trait<f32> for F8 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: f32) -> F8 {
                self.map(|a| a $op o)
            }
        }
        impl $trait<F8> for f32 {
            type Output = F8;
            #[inline(always)]
            fn $f(self, o: F8) -> F8 {
                o.map(|b| self $op b)
            }
        }
    };
}

binary!(Add, add, +);
binary!(Sub, sub, -);
binary!(Mul, mul, *);
binary!(Div, div, /);

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|a| -a)
    }
}

impl BitAnd for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitand(self, o: M8) -> M8 {
        M8(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
}

impl BitOr for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitor(self, o: M8) -> M8 {
        M8(std::array::from_fn(|i| self.0[i] | o.0[i]))
    }
}

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        M8(self.0.map(|m| !m))
    }
}

/// Three lane vectors: eight points or directions.
#[derive(Clone, Copy, Debug)]
pub struct V8 {
    /// x of every lane.
    pub x: F8,
    /// y.
    pub y: F8,
    /// z.
    pub z: F8,
}

impl V8 {
    /// Lane `i` is `f(i)`.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> [f32; 3]) -> V8 {
        let v: [[f32; 3]; LANES] = std::array::from_fn(&mut f);
        V8 {
            x: F8::from_fn(|i| v[i][0]),
            y: F8::from_fn(|i| v[i][1]),
            z: F8::from_fn(|i| v[i][2]),
        }
    }

    /// One point in every lane.
    #[inline(always)]
    pub fn splat(v: [f32; 3]) -> V8 {
        V8 {
            x: F8::splat(v[0]),
            y: F8::splat(v[1]),
            z: F8::splat(v[2]),
        }
    }

    /// Lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> [f32; 3] {
        [self.x.0[i], self.y.0[i], self.z.0[i]]
    }

    /// Lane-wise dot product, summed x, then y, then z (one order on every backend).
    #[inline(always)]
    pub fn dot(self, o: V8) -> F8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// Lane-wise cross product.
    #[inline(always)]
    pub fn cross(self, o: V8) -> V8 {
        V8 {
            x: self.y * o.z - self.z * o.y,
            y: self.z * o.x - self.x * o.z,
            z: self.x * o.y - self.y * o.x,
        }
    }

    /// Each lane times `s`'s lane.
    #[inline(always)]
    pub fn scale(self, s: F8) -> V8 {
        V8 {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }

    /// Lane-wise `m ? a : b`.
    #[inline(always)]
    pub fn select(m: M8, a: V8, b: V8) -> V8 {
        V8 {
            x: m.select(a.x, b.x),
            y: m.select(a.y, b.y),
            z: m.select(a.z, b.z),
        }
    }
}

impl Add for V8 {
    type Output = V8;
    #[inline(always)]
    fn add(self, o: V8) -> V8 {
        V8 {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

/// Lane-wise and component-wise product (colours times colours).
impl Mul for V8 {
    type Output = V8;
    #[inline(always)]
    fn mul(self, o: V8) -> V8 {
        V8 {
            x: self.x * o.x,
            y: self.y * o.y,
            z: self.z * o.z,
        }
    }
}

impl Sub for V8 {
    type Output = V8;
    #[inline(always)]
    fn sub(self, o: V8) -> V8 {
        V8 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_and_max_take_the_second_operand_for_nan() {
        let nan = F8::splat(f32::NAN);
        let one = F8::splat(1.0);
        assert_eq!(nan.min(one), one);
        assert!(one.min(nan).0[0].is_nan());
        assert_eq!(nan.max(one), one);
        assert!(one.max(nan).0[0].is_nan());
    }

    #[test]
    fn select_and_compare_are_lane_wise() {
        let a = F8::from_fn(|i| i as f32);
        let m = a.lt(F8::splat(3.0));
        assert_eq!(
            m.to_bools(),
            [true, true, true, false, false, false, false, false]
        );
        assert_eq!(m.select(a, -a).0, [0.0, 1.0, 2.0, -3.0, -4.0, -5.0, -6.0, -7.0]);
        assert_eq!(F8::splat(-0.0).sign_one(), F8::splat(-1.0));
    }
}
