//! # accd-spec
//!
//! One declaration per configuration field: its default, unit, allowed range and a one-line
//! description, written once in a [`config_struct!`] and read by everything else. From it come
//!
//! * the struct itself, its `Default` and its rustdoc (unit, range and default of every field);
//! * the range check ([`Fields::check_fields`]): every number checked against its declared
//!   interval, an error ([`OutOfRange`]) naming the dotted field, the value and the range;
//! * the field table ([`Fields::FIELDS`], [`FieldSpec`]) that the env docstrings' Arguments
//!   tables and `docs/environment.md` are generated from;
//! * for a struct that composes another one flat (`..physics: CaptureConfig;`), its serde
//!   reading and writing: the members' keys and its own side by side in one document, unknown
//!   and repeated keys refused (serde's `flatten` does not combine with `deny_unknown_fields`).
//!
//! Ranges are written as intervals with explicit bounds, `"(0, 1000]"` (0 excluded, 1000
//! included), `"[0, 1e6]"`, `"[-inf, 5]"`; `""` declares no range (a switch, a name, a list, a
//! section). Rules between fields (a flap limit within a table, a step that divides another) stay
//! with their configuration, written with [`Range`] and [`out_of_range`] too.
//!
//! Nothing here runs in a hot loop: checks run once per configuration.

#![forbid(unsafe_code)]

use std::fmt;

/// Re-exported for [`config_struct!`]'s generated code.
#[doc(hidden)]
pub use serde;

/// One field of a configuration struct as declared in its [`config_struct!`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldSpec {
    /// The key (the Rust field name); empty for a member composed flat, whose keys
    /// ([`FieldSpec::nested`]) stand beside the struct's own.
    pub name: &'static str,
    /// The unit ("-" for a number without one, "" for something that is not a number).
    pub unit: &'static str,
    /// The allowed interval, as [`Range::parse`] reads it; "" for none.
    pub range: &'static str,
    /// One line saying what the field is.
    pub description: &'static str,
    /// The default as written in the declaration (Rust source text; tables show the default's
    /// JSON where the configuration writes one).
    pub default: &'static str,
    /// The fields of a section (a field whose type is itself a configuration struct); empty for
    /// a value.
    pub nested: &'static [FieldSpec],
}

impl FieldSpec {
    /// The allowed values in words, as errors and tables print them: the interval and the unit
    /// ("(0, 5000] m"); "" without a range.
    pub fn allowed(&self) -> String {
        with_unit(self.range, self.unit)
    }
}

fn with_unit(range: &str, unit: &str) -> String {
    if range.is_empty() || unit.is_empty() || unit == "-" {
        range.to_string()
    } else {
        format!("{range} {unit}")
    }
}

/// An end of an interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    /// The end itself is excluded.
    Open(f64),
    /// The end itself is included.
    Closed(f64),
}

/// An interval of allowed values with explicit ends, e.g. `(0, 1000]`. Only finite values are
/// ever inside (an infinite end means "no limit on this side").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// Lower end.
    pub lo: Bound,
    /// Upper end.
    pub hi: Bound,
}

impl Range {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Range {
        Range {
            lo: Bound::Closed(lo),
            hi: Bound::Closed(hi),
        }
    }

    /// `(lo, hi]`.
    pub const fn open_closed(lo: f64, hi: f64) -> Range {
        Range {
            lo: Bound::Open(lo),
            hi: Bound::Closed(hi),
        }
    }

    /// Reads `"(lo, hi]"`-style text: `(` or `[`, a number (or `-inf`), a comma, a number (or
    /// `inf`), `)` or `]`. The error says what could not be read.
    pub fn parse(text: &str) -> Result<Range, String> {
        let bad = |why: &str| format!("range {text:?}: {why} (write e.g. \"(0, 1000]\")");
        let t = text.trim();
        let (open_lo, rest) = match t.chars().next() {
            Some('(') => (true, &t[1..]),
            Some('[') => (false, &t[1..]),
            _ => return Err(bad("starts with neither `(` nor `[`")),
        };
        let (open_hi, inner) = match rest.chars().last() {
            Some(')') => (true, &rest[..rest.len() - 1]),
            Some(']') => (false, &rest[..rest.len() - 1]),
            _ => return Err(bad("ends with neither `)` nor `]`")),
        };
        let Some((lo, hi)) = inner.split_once(',') else {
            return Err(bad("has no comma between its ends"));
        };
        let number = |s: &str| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| !v.is_nan())
                .ok_or_else(|| bad(&format!("`{}` is not a number", s.trim())))
        };
        let (lo, hi) = (number(lo)?, number(hi)?);
        if lo > hi {
            return Err(bad("its lower end is above its upper end"));
        }
        let end = |open: bool, v: f64| {
            if open {
                Bound::Open(v)
            } else {
                Bound::Closed(v)
            }
        };
        Ok(Range {
            lo: end(open_lo, lo),
            hi: end(open_hi, hi),
        })
    }

    /// Whether `v` is finite and inside.
    pub fn contains(&self, v: f64) -> bool {
        let above = match self.lo {
            Bound::Open(lo) => v > lo,
            Bound::Closed(lo) => v >= lo,
        };
        let below = match self.hi {
            Bound::Open(hi) => v < hi,
            Bound::Closed(hi) => v <= hi,
        };
        v.is_finite() && above && below
    }

    /// `Ok` if `value` is inside, else the error naming `field`, the value and this range
    /// followed by `unit` ("-" or "" for none).
    pub fn check(&self, field: &str, value: f64, unit: &str) -> Result<(), OutOfRange> {
        if self.contains(value) {
            Ok(())
        } else {
            Err(out_of_range(
                field,
                value,
                with_unit(&self.to_string(), unit),
            ))
        }
    }
}

impl fmt::Display for Range {
    /// `(0, 1000]`: numbers as Rust prints them.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (open, lo) = match self.lo {
            Bound::Open(v) => ('(', v),
            Bound::Closed(v) => ('[', v),
        };
        let (close, hi) = match self.hi {
            Bound::Open(v) => (')', v),
            Bound::Closed(v) => (']', v),
        };
        write!(f, "{open}{lo}, {hi}{close}")
    }
}

/// A value outside its allowed range: the dotted field, the value and the allowed values in
/// words. Each crate turns it into its own error type's out-of-range variant.
#[derive(Debug, Clone, PartialEq)]
pub struct OutOfRange {
    /// Dotted path of the field (`accd.mass`, `boom.offset[1]`).
    pub field: String,
    /// The value, printed.
    pub value: String,
    /// The allowed range (interval and unit) or rule, in words.
    pub allowed: String,
}

impl fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "`{}` = {} is outside the allowed range {}",
            self.field, self.value, self.allowed
        )
    }
}

impl std::error::Error for OutOfRange {}

/// Shorthand for an [`OutOfRange`].
pub fn out_of_range(
    field: &str,
    value: impl fmt::Display,
    allowed: impl Into<String>,
) -> OutOfRange {
    OutOfRange {
        field: field.to_owned(),
        value: value.to_string(),
        allowed: allowed.into(),
    }
}

/// Checks `value` against a declared field: its range (parsed from the declaration) and unit.
/// A number without a range must be finite.
pub fn check_number(path: &str, value: f64, spec: &FieldSpec) -> Result<(), OutOfRange> {
    if spec.range.is_empty() {
        return if value.is_finite() {
            Ok(())
        } else {
            Err(out_of_range(path, value, "a finite number"))
        };
    }
    match Range::parse(spec.range) {
        // The message carries the range as declared ("(0, 1e12]").
        Ok(range) if range.contains(value) => Ok(()),
        Ok(_) => Err(out_of_range(path, value, spec.allowed())),
        // Every declaration is parsed by the crates' tests; this is only reachable by a typo
        // that those tests would have caught.
        Err(why) => Err(out_of_range(
            path,
            value,
            format!("(bad declaration: {why})"),
        )),
    }
}

/// The dotted path of `name` inside `prefix` (the name itself at the top).
pub fn join(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_owned()
    } else if name.is_empty() {
        prefix.to_owned()
    } else {
        format!("{prefix}.{name}")
    }
}

/// A value a configuration field can hold: how it is checked against its declaration.
pub trait Field {
    /// The fields of a configuration struct (a section); empty for a value.
    const NESTED: &'static [FieldSpec] = &[];
    /// Whether the value is a number (or numbers) that a declared range applies to.
    const NUMERIC: bool;

    /// Checks the value at `path` against `spec` (for a section: its own fields).
    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange>;

    /// Whether the value is left out when a struct composed flat writes its entries
    /// ([`Fields::write_entries`]): a section says so through [`Rules::omitted`]; a value never
    /// is. A missing key reads as its default, so omission must only hold at the default.
    fn omitted(&self) -> bool {
        false
    }
}

impl Field for f64 {
    const NUMERIC: bool = true;

    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange> {
        check_number(path, *self, spec)
    }
}

impl Field for usize {
    const NUMERIC: bool = true;

    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange> {
        // Counts are far below 2^53: exact as f64. The value is printed as the integer.
        check_number(path, *self as f64, spec).map_err(|e| OutOfRange {
            value: self.to_string(),
            ..e
        })
    }
}

impl<const N: usize> Field for [f64; N] {
    const NUMERIC: bool = true;

    /// Each component against the range, named `path[i]`.
    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange> {
        for (i, v) in self.iter().enumerate() {
            check_number(&format!("{path}[{i}]"), *v, spec)?;
        }
        Ok(())
    }
}

impl<T: Field> Field for Option<T> {
    const NESTED: &'static [FieldSpec] = T::NESTED;
    const NUMERIC: bool = T::NUMERIC;

    /// `None` is always allowed; `Some` is checked as its value.
    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange> {
        match self {
            Some(v) => v.check_field(path, spec),
            None => Ok(()),
        }
    }
}

/// Declares types whose fields take no range (switches, names, seeds, lists checked by their
/// configuration's rules): [`Field`] with nothing to check.
#[macro_export]
macro_rules! no_range {
    ($($ty:ty),* $(,)?) => {
        $(impl $crate::Field for $ty {
            const NUMERIC: bool = false;

            fn check_field(&self, _path: &str, _spec: &$crate::FieldSpec) -> ::std::result::Result<(), $crate::OutOfRange> {
                Ok(())
            }
        })*
    };
}

no_range!(bool, u64, String);

impl<T: Field> Field for Vec<T> {
    const NUMERIC: bool = T::NUMERIC;

    /// Each element, named `path[i]`.
    fn check_field(&self, path: &str, spec: &FieldSpec) -> Result<(), OutOfRange> {
        for (i, v) in self.iter().enumerate() {
            v.check_field(&format!("{path}[{i}]"), spec)?;
        }
        Ok(())
    }
}

/// The rules between the fields of a configuration struct, beyond each field's declared range
/// (a centre of gravity within the body, a step dividing another). Every [`config_struct!`]
/// states its rules with an `impl Rules` (empty when there are none); [`Fields::check_fields`]
/// runs them after the ranges.
pub trait Rules {
    /// Checks the rules; errors name the dotted field under `prefix` (the struct's own path).
    fn check_rules(&self, _prefix: &str) -> Result<(), OutOfRange> {
        Ok(())
    }

    /// True when this section, as a field of a struct composed flat, is left out of the
    /// documents that struct writes (an opt-in section at its default, so that the documents,
    /// and the config hashes of saved states, of configurations without it stay as they were).
    /// Must only be true at the default (a missing key reads as the default). False unless a
    /// struct says otherwise.
    fn omitted(&self) -> bool {
        false
    }
}

/// A configuration struct declared with [`config_struct!`].
pub trait Fields: Sized {
    /// Its fields in declaration order (a member composed flat first, with an empty name).
    const FIELDS: &'static [FieldSpec];

    /// Checks every field against its declared range, sections included, then the struct's
    /// [`Rules`]; `prefix` is the struct's own dotted path ("" at the top).
    fn check_fields(&self, prefix: &str) -> Result<(), OutOfRange>;

    /// The declaration of the field `name` (of this struct, or of a member composed flat).
    fn field(name: &str) -> Option<&'static FieldSpec> {
        fn find(fields: &'static [FieldSpec], name: &str) -> Option<&'static FieldSpec> {
            fields.iter().find_map(|f| {
                if f.name.is_empty() {
                    find(f.nested, name)
                } else {
                    (f.name == name).then_some(f)
                }
            })
        }
        find(Self::FIELDS, name)
    }

    /// Reads the value of key `key` from `map` into its field, if the key is one of this
    /// struct's (a flat member's included); false (nothing read) otherwise.
    fn read_key<'de, A: serde::de::MapAccess<'de>>(
        &mut self,
        key: &str,
        map: &mut A,
    ) -> Result<bool, A::Error>;

    /// Writes every field as an entry of `map`, in declaration order (a section whose
    /// [`Rules::omitted`] is true left out).
    fn write_entries<S: serde::ser::SerializeMap>(&self, map: &mut S) -> Result<(), S::Error>;
}

/// Every field of `fields` with its dotted key (sections descended into, flat members
/// inlined), in declaration order: what the documentation tables list. Each entry: the dotted
/// key and the declaration (a section, `nested` not empty, comes before its fields).
pub fn walk(fields: &'static [FieldSpec]) -> Vec<(String, &'static FieldSpec)> {
    fn go(prefix: &str, fields: &'static [FieldSpec], out: &mut Vec<(String, &'static FieldSpec)>) {
        for f in fields {
            let key = join(prefix, f.name);
            if !f.name.is_empty() {
                out.push((key.clone(), f));
            }
            go(&key, f.nested, out);
        }
    }
    let mut out = Vec::new();
    go("", fields, &mut out);
    out
}

/// Declares a configuration struct, one line a field:
///
/// ```text
/// /// extra docs (optional)
/// pub mass: f64 = 50.0, "kg", "(0, 1000]", "mass of the device";
/// //  name  type  default unit  range       one-line description
/// ```
///
/// and generates the struct (each field documented with its description, unit, range and
/// default), `Default` from the defaults, and [`Fields`] (the field table, the range check, the
/// key-by-key reading and writing). A first line `..name: Type;` composes another configuration
/// struct flat: its keys stand beside this struct's in one document, and this struct's serde
/// `Serialize`/`Deserialize` are generated (unknown and repeated keys refused); without it,
/// derive serde as usual. Units: SI, "-" for a number without one, "" for what is not a number.
/// Types of fields implement [`Field`] ([`no_range!`] for those without a range); the struct
/// implements [`Rules`].
#[macro_export]
macro_rules! config_struct {
    (
        $(#[$smeta:meta])*
        $svis:vis struct $name:ident {
            $(.. $flat:ident : $flat_ty:ty;)?
            $(
                $(#[$fmeta:meta])*
                $fvis:vis $field:ident : $fty:ty = $default:expr, $unit:literal, $range:literal, $desc:literal;
            )*
        }
    ) => {
        $(#[$smeta])*
        $svis struct $name {
            $(
                #[doc = concat!("The keys of [`", stringify!($flat_ty), "`], written beside this struct's own (composed flat).")]
                pub $flat: $flat_ty,
            )?
            $(
                #[doc = concat!(" ", $desc, ".")]
                #[doc = ""]
                $(#[$fmeta])*
                #[doc = ""]
                #[doc = concat!(" Unit `", $unit, "`; range `", $range, "`; default `", stringify!($default), "`.")]
                $fvis $field: $fty,
            )*
        }

        impl ::std::default::Default for $name {
            fn default() -> Self {
                $name {
                    $($flat: ::std::default::Default::default(),)?
                    $($field: $default,)*
                }
            }
        }

        impl $crate::Fields for $name {
            const FIELDS: &'static [$crate::FieldSpec] = &[
                $($crate::FieldSpec {
                    name: "",
                    unit: "",
                    range: "",
                    description: stringify!($flat),
                    default: "",
                    nested: <$flat_ty as $crate::Fields>::FIELDS,
                },)?
                $($crate::FieldSpec {
                    name: stringify!($field),
                    unit: $unit,
                    range: $range,
                    description: $desc,
                    default: stringify!($default),
                    nested: <$fty as $crate::Field>::NESTED,
                },)*
            ];

            fn check_fields(&self, prefix: &str) -> ::std::result::Result<(), $crate::OutOfRange> {
                $($crate::Fields::check_fields(&self.$flat, prefix)?;)?
                // The declarations of the struct's own fields, in order (a flat member's entry
                // has no name).
                let mut _specs = <Self as $crate::Fields>::FIELDS.iter().filter(|f| !f.name.is_empty());
                $(if let Some(spec) = _specs.next() {
                    $crate::Field::check_field(&self.$field, &$crate::join(prefix, stringify!($field)), spec)?;
                })*
                $crate::Rules::check_rules(self, prefix)
            }

            fn read_key<'de, A: $crate::serde::de::MapAccess<'de>>(
                &mut self,
                key: &str,
                map: &mut A,
            ) -> ::std::result::Result<bool, A::Error> {
                $(if $crate::Fields::read_key(&mut self.$flat, key, map)? {
                    return Ok(true);
                })?
                match key {
                    $(stringify!($field) => self.$field = map.next_value()?,)*
                    _ => return Ok(false),
                }
                Ok(true)
            }

            fn write_entries<S: $crate::serde::ser::SerializeMap>(
                &self,
                map: &mut S,
            ) -> ::std::result::Result<(), S::Error> {
                $($crate::Fields::write_entries(&self.$flat, map)?;)?
                $(if !$crate::Field::omitted(&self.$field) {
                    map.serialize_entry(stringify!($field), &self.$field)?;
                })*
                Ok(())
            }
        }

        impl $crate::Field for $name {
            const NESTED: &'static [$crate::FieldSpec] = <$name as $crate::Fields>::FIELDS;
            const NUMERIC: bool = false;

            fn check_field(&self, path: &str, _spec: &$crate::FieldSpec) -> ::std::result::Result<(), $crate::OutOfRange> {
                $crate::Fields::check_fields(self, path)
            }

            fn omitted(&self) -> bool {
                $crate::Rules::omitted(self)
            }
        }

        $($crate::flat_serde!($name, $flat);)?
    };
}

/// The serde `Serialize`/`Deserialize` of a [`config_struct!`] with a flat member (`$flat` names
/// it only to make this expansion conditional on it).
#[doc(hidden)]
#[macro_export]
macro_rules! flat_serde {
    ($name:ident, $flat:ident) => {
        impl $crate::serde::Serialize for $name {
            fn serialize<S: $crate::serde::Serializer>(
                &self,
                serializer: S,
            ) -> ::std::result::Result<S::Ok, S::Error> {
                use $crate::serde::ser::SerializeMap;
                let mut map = serializer.serialize_map(None)?;
                $crate::Fields::write_entries(self, &mut map)?;
                map.end()
            }
        }

        impl<'de> $crate::serde::Deserialize<'de> for $name {
            fn deserialize<D: $crate::serde::Deserializer<'de>>(
                deserializer: D,
            ) -> ::std::result::Result<Self, D::Error> {
                $crate::deserialize_flat(deserializer, stringify!($name))
            }
        }
    };
}

/// Reads a struct composed flat ([`config_struct!`] with a `..member;` line) from a map: every
/// key goes to the field (of the struct or of its flat member) that declares it; missing keys
/// keep their defaults; an unknown key is refused with the keys allowed, a repeated one as
/// repeated.
#[doc(hidden)]
pub fn deserialize_flat<'de, T, D>(deserializer: D, name: &'static str) -> Result<T, D::Error>
where
    T: Fields + Default,
    D: serde::Deserializer<'de>,
{
    struct FlatVisitor<T>(std::marker::PhantomData<T>, &'static str);

    impl<'de, T: Fields + Default> serde::de::Visitor<'de> for FlatVisitor<T> {
        type Value = T;

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "a {} object", self.1)
        }

        fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<T, A::Error> {
            let mut value = T::default();
            let mut seen: Vec<String> = Vec::new();
            while let Some(key) = map.next_key::<String>()? {
                if seen.contains(&key) {
                    return Err(serde::de::Error::custom(format_args!(
                        "duplicate field `{key}`"
                    )));
                }
                if !value.read_key(&key, &mut map)? {
                    let keys: Vec<String> = walk(T::FIELDS)
                        .into_iter()
                        .map(|(k, _)| k)
                        .filter(|k| !k.contains('.'))
                        .map(|k| format!("`{k}`"))
                        .collect();
                    return Err(serde::de::Error::custom(format_args!(
                        "unknown field `{key}`, expected one of {}",
                        keys.join(", ")
                    )));
                }
                seen.push(key);
            }
            Ok(value)
        }
    }

    deserializer.deserialize_map(FlatVisitor(std::marker::PhantomData, name))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_with_explicit_ends() {
        let r = Range::parse("(0, 1000]").unwrap();
        assert_eq!(r, Range::open_closed(0.0, 1000.0));
        assert!(!r.contains(0.0) && r.contains(1e-300) && r.contains(1000.0));
        assert!(!r.contains(1000.0000001) && !r.contains(f64::NAN));
        let r = Range::parse("[-inf, 5)").unwrap();
        assert!(r.contains(-1e300) && !r.contains(f64::NEG_INFINITY) && !r.contains(5.0));
        assert_eq!(
            Range::parse(" [1e-4, 0.1] ").unwrap(),
            Range::closed(1e-4, 0.1)
        );
        for bad in [
            "0, 1]", "(0, 1", "(0 1]", "(a, 1]", "(2, 1]", "(nan, 1]", "",
        ] {
            assert!(Range::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn errors_name_field_value_and_range() {
        let spec = FieldSpec {
            name: "length",
            unit: "m",
            range: "(0, 5000]",
            description: "length",
            default: "250.0",
            nested: &[],
        };
        let e = check_number("tether.length", -3.0, &spec).unwrap_err();
        assert_eq!(
            e.to_string(),
            "`tether.length` = -3 is outside the allowed range (0, 5000] m"
        );
        let e = [1.0, 6000.0].check_field("x", &spec).unwrap_err();
        assert_eq!((e.field.as_str(), e.value.as_str()), ("x[1]", "6000"));
        let e = 0usize
            .check_field(
                "segments",
                &FieldSpec {
                    range: "[1, 1000]",
                    unit: "-",
                    ..spec
                },
            )
            .unwrap_err();
        assert_eq!(e.allowed, "[1, 1000]");
        let free = FieldSpec { range: "", ..spec };
        assert!(check_number("a", 1e300, &free).is_ok());
        assert!(check_number("a", f64::INFINITY, &free).is_err());
    }
}
