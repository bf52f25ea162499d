//! The variable table: one source of truth per variable.
//!
//! A model declares its variables once with [`variables!`](crate::variables!). The macro
//! generates a plain struct with one typed field per variable (what the model's equations
//! read and write) and the table of [`VarInfo`] that drives the runtime (value references,
//! causality checks, ranges) and generates `modelDescription.xml` and the documentation.

pub use tb_fmi::schema::{format_real, Causality, Initial, ScalarType, Variability};
pub use tb_fmi::units::UnitDef;

/// A typed scalar value. Strings appear here only as start values of the table (a
/// String variable's value at run time is read and written with
/// [`VarTable::get_str`]/[`VarTable::set_str`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Real(f64),
    Integer(i32),
    Boolean(bool),
    Str(&'static str),
}

/// A field's value from a [`Value`] of its kind (`f64` from a Real, `i32` from an Integer or
/// an Enumeration's, `bool` from a Boolean); `Err` gives back a value of another kind.
macro_rules! field_from_value {
    ($($t:ty: $kind:ident),*) => {$(
        impl TryFrom<Value> for $t {
            type Error = Value;
            fn try_from(v: Value) -> Result<$t, Value> {
                match v {
                    Value::$kind(x) => Ok(x),
                    other => Err(other),
                }
            }
        }
    )*};
}

field_from_value!(f64: Real, i32: Integer, bool: Boolean);

impl Value {
    pub const fn var_type(self) -> ScalarType {
        match self {
            Value::Real(_) => ScalarType::Real,
            Value::Integer(_) => ScalarType::Integer,
            Value::Boolean(_) => ScalarType::Boolean,
            Value::Str(_) => ScalarType::String,
        }
    }

    /// The value as a number (booleans as 0/1), for range checks and documentation; NaN for
    /// a string.
    pub const fn as_f64(self) -> f64 {
        match self {
            Value::Real(x) => x,
            Value::Integer(i) => i as f64,
            Value::Boolean(b) => b as i32 as f64,
            Value::Str(_) => f64::NAN,
        }
    }

    /// The value as written in modelDescription.xml (shortest round-trip form; a string as
    /// it is, to be escaped by the writer).
    pub fn xml_text(self) -> String {
        match self {
            Value::Real(x) => format_real(x),
            Value::Integer(i) => i.to_string(),
            Value::Boolean(b) => b.to_string(),
            Value::Str(s) => s.to_string(),
        }
    }
}

/// An FMI Enumeration type: its name (`declaredType`), what it means, and its items. Values
/// travel as Integers (fmi2GetInteger/fmi2SetInteger); the items' values are 1, 2, … in
/// order ([`crate::check`] requires it), so the declared range is the item set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnumerationType {
    pub name: &'static str,
    pub description: &'static str,
    pub items: &'static [EnumerationItem],
}

/// One item of an [`EnumerationType`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnumerationItem {
    pub name: &'static str,
    pub value: i32,
    pub description: &'static str,
}

impl EnumerationType {
    /// The item of value `value`.
    pub fn item(&self, value: i32) -> Option<&EnumerationItem> {
        self.items.iter().find(|i| i.value == value)
    }

    /// `1 first_order, 2 second_order`: the items for a message.
    pub fn listed(&self) -> String {
        self.items
            .iter()
            .map(|i| format!("{} {}", i.value, i.name))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Each unit the variables of `table` use, once, in the order of their names: the model's
/// own definition where it gave one, else the shared table's.
pub fn used_units(table: &[VarInfo]) -> Vec<&'static UnitDef> {
    let mut units: Vec<&'static UnitDef> = table
        .iter()
        .filter_map(|v| {
            v.unit_definition
                .or_else(|| v.unit.and_then(tb_fmi::units::lookup))
        })
        .collect();
    units.sort_unstable_by(|a, b| a.name.cmp(b.name));
    units.dedup_by(|a, b| a.name == b.name);
    units
}

/// Everything modelDescription.xml and the runtime know about one variable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VarInfo {
    pub name: &'static str,
    pub value_reference: u32,
    /// Start value; its type is the variable's type.
    pub start: Value,
    pub causality: Causality,
    pub variability: Variability,
    /// `None`: the standard's default for this causality/variability.
    pub initial: Option<Initial>,
    /// Unit name, one of [`crate::units::UNITS`] or the model's own ([`Self::own_unit`]);
    /// `None` for dimensionless flags and modes.
    pub unit: Option<&'static str>,
    /// The model's own definition of [`Self::unit`], for a unit the shared table does not
    /// know; `None`: the shared table's.
    pub unit_definition: Option<&'static UnitDef>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub description: &'static str,
    /// For outputs: value references of the inputs it depends on directly (feed-through).
    /// In [`variables!`](crate::variables!) written as the inputs' names.
    pub depends_on: &'static [u32],
    /// An Enumeration's type (the variable is then an `Enumeration` of it, an i32 field).
    pub enumeration: Option<&'static EnumerationType>,
    /// For outputs: the further inputs (or parameters) it depends on in initialization mode
    /// only (where the model computes it from its inputs before the first step).
    pub init_depends_on: &'static [u32],
}

const fn base(vr: u32, causality: Causality, variability: Variability) -> VarInfo {
    VarInfo {
        name: "",
        value_reference: vr,
        start: Value::Real(0.0),
        causality,
        variability,
        initial: None,
        unit: None,
        unit_definition: None,
        min: None,
        max: None,
        description: "",
        depends_on: &[],
        enumeration: None,
        init_depends_on: &[],
    }
}

/// A value reference left to [`variables!`](crate::variables!): the variable's position in the
/// table (0, 1, 2, ... in declaration order), as rust-fmi and the Reference FMUs number them.
/// For a new model, written in all of its lines: a table that mixes `AUTO` with explicit
/// numbers is refused at compile time where a position meets an explicit number. A published
/// model keeps its explicit numbers, because hosts and system files may hold them.
pub const AUTO: u32 = u32::MAX;

/// A fixed parameter (set before initialisation, constant during the run).
pub const fn parameter(vr: u32) -> VarInfo {
    base(vr, Causality::Parameter, Variability::Fixed)
}

/// A tunable parameter (may change between steps).
pub const fn tunable(vr: u32) -> VarInfo {
    base(vr, Causality::Parameter, Variability::Tunable)
}

/// A continuous input.
pub const fn input(vr: u32) -> VarInfo {
    base(vr, Causality::Input, Variability::Continuous)
}

/// A discrete input (a mode switch, a flag).
pub const fn discrete_input(vr: u32) -> VarInfo {
    base(vr, Causality::Input, Variability::Discrete)
}

/// A continuous output, computed by the model (initial="calculated").
pub const fn output(vr: u32) -> VarInfo {
    base(vr, Causality::Output, Variability::Continuous)
}

/// A discrete output (a counter, a flag), computed by the model.
pub const fn discrete_output(vr: u32) -> VarInfo {
    base(vr, Causality::Output, Variability::Discrete)
}

/// A local variable exposed for inspection (a state, an internal signal).
pub const fn local(vr: u32) -> VarInfo {
    base(vr, Causality::Local, Variability::Continuous)
}

impl VarInfo {
    /// The value reference [`AUTO`] resolved to the variable's `position` in its table (other
    /// value references stay as written).
    #[doc(hidden)]
    pub const fn numbered(mut self, position: u32) -> Self {
        if self.value_reference == AUTO {
            self.value_reference = position;
        }
        self
    }

    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = Some(unit);
        self
    }
    /// A unit of the model's own, defined in the model's crate (`UnitDef::named("s/m")
    /// .s(1).m(-1)`): declared in the model description like the shared table's units, with
    /// no edit elsewhere. The check refuses a name the shared table defines differently.
    pub const fn own_unit(mut self, definition: &'static UnitDef) -> Self {
        self.unit = Some(definition.name);
        self.unit_definition = Some(definition);
        self
    }
    pub const fn min(mut self, min: f64) -> Self {
        self.min = Some(min);
        self
    }
    pub const fn max(mut self, max: f64) -> Self {
        self.max = Some(max);
        self
    }
    pub const fn range(self, min: f64, max: f64) -> Self {
        self.min(min).max(max)
    }
    pub const fn describe(mut self, description: &'static str) -> Self {
        self.description = description;
        self
    }
    pub const fn initial(mut self, initial: Initial) -> Self {
        self.initial = Some(initial);
        self
    }
    /// The inputs an output depends on directly (feed-through). In
    /// [`variables!`](crate::variables!) name them: `.depends_on(&[omega_left, omega_right])`
    /// (each field name is a constant holding its value reference there).
    pub const fn depends_on(mut self, inputs: &'static [u32]) -> Self {
        self.depends_on = inputs;
        self
    }
    /// Inputs (or parameters) an output depends on in initialization mode beyond
    /// [`Self::depends_on`], named like them.
    pub const fn init_depends_on(mut self, inputs: &'static [u32]) -> Self {
        self.init_depends_on = inputs;
        self
    }
    /// An Enumeration of `t`: its range is the items' (their values are 1, 2, … in order).
    pub const fn items(mut self, t: &'static EnumerationType) -> Self {
        self.enumeration = Some(t);
        if !t.items.is_empty() {
            self.min = Some(t.items[0].value as f64);
            self.max = Some(t.items[t.items.len() - 1].value as f64);
        }
        self
    }
    #[doc(hidden)]
    pub const fn named(mut self, name: &'static str, start: Value) -> Self {
        self.name = name;
        self.start = start;
        self
    }

    pub const fn var_type(&self) -> ScalarType {
        match self.enumeration {
            Some(_) => ScalarType::Enumeration,
            None => self.start.var_type(),
        }
    }

    /// The `initial` attribute in force (explicit or the standard's default, FMI 2.0 §2.2.7).
    pub const fn effective_initial(&self) -> Option<Initial> {
        if self.initial.is_some() {
            return self.initial;
        }
        match (self.causality, self.variability) {
            (Causality::Parameter, _) => Some(Initial::Exact),
            (Causality::CalculatedParameter, _) => Some(Initial::Calculated),
            (Causality::Output, Variability::Constant)
            | (Causality::Local, Variability::Constant) => Some(Initial::Exact),
            (Causality::Output, _) | (Causality::Local, _) => Some(Initial::Calculated),
            (Causality::Input, _) | (Causality::Independent, _) => None,
        }
    }

    /// Whether modelDescription.xml carries a start value for this variable.
    pub const fn has_start(&self) -> bool {
        matches!(self.causality, Causality::Input)
            || matches!(
                self.effective_initial(),
                Some(Initial::Exact) | Some(Initial::Approx)
            )
    }
}

/// Whether a variable of `table` declares direct feed-through.
pub const fn declares_feedthrough(table: &[VarInfo]) -> bool {
    let mut i = 0;
    while i < table.len() {
        if !table[i].depends_on.is_empty() {
            return true;
        }
        i += 1;
    }
    false
}

/// What the generated variable struct provides to the runtime.
pub trait VarTable: Clone + Default + Send + 'static {
    /// The table, in declaration order.
    const VARIABLES: &'static [VarInfo];

    /// Byte offset of each variable's field in the struct when it is a Real (an `f64`),
    /// `usize::MAX` otherwise: the runtime reads and writes Reals there directly.
    const REAL_OFFSETS: &'static [usize];

    /// Whether an output declares direct feed-through (`depends_on`): the runtime then
    /// recalculates the outputs when inputs change between steps.
    const HAS_FEEDTHROUGH: bool = declares_feedthrough(Self::VARIABLES);

    /// Value of the variable at `index` in [`Self::VARIABLES`].
    fn get(&self, index: usize) -> Value;

    /// Set the variable at `index`; `false` when `value` has another type.
    fn set(&mut self, index: usize, value: Value) -> bool;

    /// The String variable at `index` (None: not a String).
    fn get_str(&self, index: usize) -> Option<&str>;

    /// Set the String variable at `index`; `false` when it is not a String.
    fn set_str(&mut self, index: usize, value: &str) -> bool;

    /// Index in the table of the variable named `name`.
    fn index_of(name: &str) -> Option<usize> {
        Self::VARIABLES.iter().position(|v| v.name == name)
    }

    /// Value reference of the variable named `name`.
    fn vr_of(name: &str) -> Option<u32> {
        Self::index_of(name).map(|i| Self::VARIABLES[i].value_reference)
    }
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_type {
    (Real) => {
        f64
    };
    (Integer) => {
        i32
    };
    (Enumeration) => {
        i32
    };
    (Boolean) => {
        bool
    };
    (String) => {
        ::std::string::String
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_init {
    (String, $e:expr) => {
        ::std::string::String::from($e)
    };
    ($t:ident, $e:expr) => {
        $e
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_get {
    (String, $place:expr) => {{
        let _ = &$place;
        $crate::variables::Value::Str("")
    }};
    ($t:ident, $place:expr) => {
        $crate::__fmi_value!($t, $place)
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_get_str {
    (String, $place:expr) => {
        Some($place.as_str())
    };
    ($t:ident, $place:expr) => {{
        let _ = &$place;
        None
    }};
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_set_str {
    (String, $place:expr, $v:expr) => {{
        $place.clear();
        $place.push_str($v);
        true
    }};
    ($t:ident, $place:expr, $v:expr) => {{
        let _ = (&$place, $v);
        false
    }};
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_value {
    (Real, $e:expr) => {
        $crate::variables::Value::Real($e)
    };
    (Integer, $e:expr) => {
        $crate::variables::Value::Integer($e)
    };
    // An Enumeration's value travels as an Integer (its table entry says which type).
    (Enumeration, $e:expr) => {
        $crate::variables::Value::Integer($e)
    };
    (Boolean, $e:expr) => {
        $crate::variables::Value::Boolean($e)
    };
    (String, $e:expr) => {
        $crate::variables::Value::Str($e)
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_set {
    (String, $place:expr, $v:expr) => {{
        let _ = &$place;
        let _ = $v;
        false
    }};
    // A number into its field when it is of the field's kind (an Enumeration's travels as
    // an Integer): `TryFrom<Value>` of the field's type.
    ($t:ident, $place:expr, $v:expr) => {
        match ::core::convert::TryFrom::try_from($v) {
            Ok(x) => {
                $place = x;
                true
            }
            Err(_) => false,
        }
    };
}

#[doc(hidden)]
#[macro_export]
macro_rules! __fmi_real_offset {
    (Real, $name:ident, $field:ident) => {
        ::core::mem::offset_of!($name, $field)
    };
    ($other:ident, $name:ident, $field:ident) => {
        usize::MAX
    };
}

/// Declare a model's variables once: a typed struct plus its [`VarTable`].
///
/// Each line is `name: Type = start => kind(value_reference).attributes…`. Value references
/// are explicit numbers (a published FMU's references never change), or [`AUTO`] in every
/// line of a new model's table: then the declaration order numbers them 0, 1, 2, ...
/// Dependencies name variables: inside the table every field name is a constant holding its
/// value reference.
/// The table is checked at compile time ([`crate::check`]): a duplicate value reference, a
/// `depends_on` naming something other than an input, a start value outside min/max, an
/// unknown unit, a missing description, ... fail the build with a message naming the
/// variables.
///
/// ```
/// use fmu_export::variables::*;
/// fmu_export::variables! {
///     /// Variables of a spring.
///     pub struct SpringVars {
///         /// The spring rate.
///         stiffness: Real = 1000.0 => parameter(1).unit("N/m").range(1.0, 1e9)
///             .describe("Spring rate"),
///         travel: Real = 0.0 => input(3).unit("m").describe("Spring travel"),
///         force: Real = 0.0 => output(2).unit("N").depends_on(&[travel])
///             .describe("Spring force"),
///     }
/// }
/// let v = SpringVars::default();
/// assert_eq!(v.stiffness, 1000.0);
/// assert_eq!(SpringVars::vr_of("force"), Some(2));
/// assert_eq!(SpringVars::VARIABLES[2].depends_on, &[3]);
///
/// // A new model's table may leave the numbers to the declaration order.
/// fmu_export::variables! {
///     pub struct DamperVars {
///         rate: Real = 500.0 => parameter(AUTO).unit("N.s/m").range(1.0, 1e9)
///             .describe("Damper rate"),
///         speed: Real = 0.0 => input(AUTO).unit("m/s").describe("Damper speed"),
///         force: Real = 0.0 => output(AUTO).unit("N").depends_on(&[speed])
///             .describe("Damper force"),
///     }
/// }
/// assert_eq!(DamperVars::vr_of("rate"), Some(0));
/// assert_eq!(DamperVars::vr_of("force"), Some(2));
/// assert_eq!(DamperVars::VARIABLES[2].depends_on, &[1]);
/// ```
///
/// A position that meets an explicit number fails the build, naming both variables:
///
/// ```compile_fail
/// use fmu_export::variables::*;
/// fmu_export::variables! {
///     pub struct MixedVars {
///         a: Real = 0.0 => input(AUTO).unit("m").describe("position 0"),
///         b: Real = 0.0 => output(0).unit("m").describe("explicitly 0"),
///     }
/// }
/// ```
#[macro_export]
macro_rules! variables {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[$fmeta:meta])*
                $field:ident : $ty:ident = $start:expr => $info:expr
            ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Debug, PartialEq)]
        $vis struct $name {
            $( $(#[$fmeta])* pub $field: $crate::__fmi_type!($ty), )*
        }

        impl ::core::default::Default for $name {
            fn default() -> Self {
                Self { $( $field: $crate::__fmi_init!($ty, $start), )* }
            }
        }

        impl $crate::variables::VarTable for $name {
            const VARIABLES: &'static [$crate::variables::VarInfo] = {
                // Each field's position in the table, for an AUTO value reference.
                #[allow(non_camel_case_types, dead_code)]
                #[repr(u32)]
                enum Position { $($field),* }
                // Every field's name as a constant holding its value reference, so that
                // `depends_on(&[u, v])` names variables (macro_rules items are not hygienic:
                // the names in `$info` resolve to these).
                $(
                    #[allow(non_upper_case_globals, dead_code)]
                    const $field: u32 = ($info).numbered(Position::$field as u32).value_reference;
                )*
                &[ $(
                    ($info)
                        .numbered(Position::$field as u32)
                        .named(stringify!($field), $crate::__fmi_value!($ty, $start)),
                )* ]
            };

            const REAL_OFFSETS: &'static [usize] = &[
                $( $crate::__fmi_real_offset!($ty, $name, $field), )*
            ];

            #[inline]
            fn get(&self, index: usize) -> $crate::variables::Value {
                const GET: &[fn(&$name) -> $crate::variables::Value] =
                    &[ $( |s: &$name| $crate::__fmi_get!($ty, s.$field), )* ];
                GET[index](self)
            }

            fn get_str(&self, index: usize) -> ::core::option::Option<&str> {
                const GET: &[for<'a> fn(&'a $name) -> ::core::option::Option<&'a str>] =
                    &[ $( |s: &$name| $crate::__fmi_get_str!($ty, s.$field), )* ];
                GET[index](self)
            }

            fn set_str(&mut self, index: usize, value: &str) -> bool {
                const SET: &[fn(&mut $name, &str) -> bool] =
                    &[ $( |s: &mut $name, v: &str| $crate::__fmi_set_str!($ty, s.$field, v), )* ];
                SET[index](self, value)
            }

            #[inline]
            fn set(&mut self, index: usize, value: $crate::variables::Value) -> bool {
                const SET: &[fn(&mut $name, $crate::variables::Value) -> bool] =
                    &[ $( |s: &mut $name, v: $crate::variables::Value| $crate::__fmi_set!($ty, s.$field, v), )* ];
                SET[index](self, value)
            }
        }

        // The table's rules (crate::check), at compile time: a broken one fails the build.
        const _: () = $crate::check::assert_table(
            <$name as $crate::variables::VarTable>::VARIABLES,
        );
    };
}
