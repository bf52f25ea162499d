//! One declaration per FMI Enumeration: the Rust enum the model's equations match on and
//! the [`EnumerationType`](crate::variables::EnumerationType) the model description
//! declares, from one list of items, so that the two cannot drift apart and no equation
//! matches on a bare integer.

/// Declare an FMI Enumeration: a Rust enum and its [`EnumerationType`] constant.
///
/// The items take the values 1, 2, … in the order written (what [`crate::check`] requires
/// of an Enumeration). Each item is `Variant = "name_in_the_description" => "what it means"`.
/// A variable of the type is declared in [`variables!`](crate::variables!) as
/// `x: Enumeration = 1 => parameter(n).items(&TABLE)`; its field is the value that travels
/// (an Integer), and the model reads it with `Type::of(x)`.
///
/// ```
/// fmu_export::enumeration! {
///     /// How the valve moves.
///     pub enum ValveMode in VALVE_MODE {
///         description: "How the valve moves",
///         Linear = "linear" => "opening proportional to the command",
///         Bang = "bang" => "fully open above half the command, else shut",
///     }
/// }
/// assert_eq!(ValveMode::of(2), ValveMode::Bang);
/// assert_eq!(ValveMode::Bang.value(), 2);
/// assert_eq!(VALVE_MODE.name, "ValveMode");
/// assert_eq!(VALVE_MODE.items[0].name, "linear");
/// assert_eq!(ValveMode::from_value(3), None);
/// ```
///
/// [`EnumerationType`]: crate::variables::EnumerationType
#[macro_export]
macro_rules! enumeration {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident in $table:ident {
            description: $description:literal,
            $first:ident = $first_item:literal => $first_meaning:literal
            $(, $variant:ident = $item:literal => $meaning:literal)* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[repr(i32)]
        $vis enum $name {
            #[doc = $first_meaning]
            $first = 1,
            $( #[doc = $meaning] $variant, )*
        }

        #[doc = concat!("`", stringify!($name), "` as the model description declares it.")]
        $vis const $table: $crate::variables::EnumerationType =
            $crate::variables::EnumerationType {
                name: stringify!($name),
                description: $description,
                items: &[
                    $crate::variables::EnumerationItem {
                        name: $first_item,
                        value: $name::$first as i32,
                        description: $first_meaning,
                    },
                    $(
                        $crate::variables::EnumerationItem {
                            name: $item,
                            value: $name::$variant as i32,
                            description: $meaning,
                        },
                    )*
                ],
            };

        impl $name {
            /// Every item, in the order of their values.
            pub const ALL: &'static [$name] = &[$name::$first $(, $name::$variant)*];

            /// The item of an Integer value, `None` outside the items.
            pub fn from_value(value: i32) -> ::core::option::Option<$name> {
                Self::ALL.iter().copied().find(|item| item.value() == value)
            }

            /// The item of a variable's value. A value outside the items can only come in
            /// when the model's range check lets it through with a warning; it means the
            /// first item, the default.
            pub fn of(value: i32) -> $name {
                Self::from_value(value).unwrap_or($name::$first)
            }

            /// The Integer value that travels through `fmi2SetInteger`/`fmi3SetInt64`.
            pub const fn value(self) -> i32 {
                self as i32
            }
        }
    };
}
