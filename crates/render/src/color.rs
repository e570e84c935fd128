//! Colour spaces. The file stores voxel colours as sRGB bytes (what `voxlod render` writes to
//! its picture as they are); glTF defines vertex colours (`COLOR_0`) as **linear** (glTF 2.0,
//! section 3.7.2.1 "Overview": "color ... in linear space"), and its consumers (three.js,
//! CesiumJS, Blender) convert them to sRGB for display. So the exports write the linear value
//! of each stored sRGB byte, by the sRGB transfer function (IEC 61966-2-1).

/// The linear value (0..=1) of the sRGB byte `c`.
pub fn srgb_to_linear(c: u8) -> f64 {
    let s = c as f64 / 255.0;
    if s <= 0.04045 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB byte of the linear value `l` (0..=1, clamped), rounded to nearest.
pub fn linear_to_srgb(l: f64) -> u8 {
    let l = l.clamp(0.0, 1.0);
    let s = if l <= 0.003_130_8 {
        l * 12.92
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// The linear value of each sRGB byte as a normalized `u16` (exact round trip through
/// [`linear_to_srgb`]).
pub fn srgb_to_linear_u16_table() -> [u16; 256] {
    std::array::from_fn(|c| (srgb_to_linear(c as u8) * 65535.0).round() as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn u16_linear_round_trips_every_srgb_byte() {
        let t = srgb_to_linear_u16_table();
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb(t[c as usize] as f64 / 65535.0), c);
        }
        // fixed points and a known mid value: sRGB 128 is 21.6 % linear
        assert_eq!((t[0], t[255]), (0, 65535));
        assert!((srgb_to_linear(128) - 0.2158605).abs() < 1e-6);
    }
}
