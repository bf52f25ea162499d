//! The importer's errors, each naming the file or instance and what was expected.

use crate::functions::Function;
use crate::status::{CallStatus, FmiFunction};
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum FmuError {
    #[error("{path}: cannot load shared library: {message}")]
    Load { path: PathBuf, message: String },
    #[error("{path}: required FMI function {symbol} is not exported")]
    MissingSymbol { path: PathBuf, symbol: &'static str },
    #[error("instance '{instance}': {message}")]
    Instantiate { instance: String, message: String },
    /// An FMI call of either version that did not return OK or Warning: the one error every
    /// instance's calls become ([`FmuError::call`]).
    #[error(
        "instance '{instance}' at t = {time} s: {function} returned {status}{}",
        format_log(log)
    )]
    Call {
        instance: String,
        function: FmiFunction,
        status: CallStatus,
        time: f64,
        log: Vec<String>,
    },
    /// An FMI 3.0 step that returned early although the instance was told it may not
    /// (`earlyReturnAllowed = false`, FMI 3.0 §4.2.1): taking it as complete would be a silent
    /// wrong result.
    #[error(
        "instance '{instance}' at t = {time} s: fmi3DoStep returned earlyReturn = true with lastSuccessfulTime = {last:?} s instead of completing the step to {target:?} s, although it was instantiated with earlyReturnAllowed = false (FMI 3.0 §4.2.1){}",
        format_log(log)
    )]
    EarlyReturn {
        instance: String,
        time: f64,
        last: f64,
        target: f64,
        log: Vec<String>,
    },
    /// A Model Exchange instance's error: an FMI call, or the integrator (CVODE) with its
    /// return flag's name, e.g. `CVode returned CV_CONV_FAILURE (-4): ...`.
    #[error(
        "{}: instance '{instance}' (Model Exchange) at t = {time} s: {call} {problem}{}",
        fmu.display(),
        format_log(log)
    )]
    ModelExchange {
        /// The .fmu the user gave (boxed, as `call`: the error stays small).
        fmu: Box<std::path::Path>,
        instance: String,
        time: f64,
        /// The FMI function (`fmi2GetDerivatives`) or the solver's (`CVode`).
        call: Box<str>,
        /// What went wrong: `returned fmi2Error`, `returned CV_CONV_FAILURE (-4): ...`.
        problem: String,
        log: Vec<String>,
    },
    /// A get or set given value references and values of different lengths (a caller's
    /// mistake, refused before the FMU could read or write past the values).
    #[error(
        "instance '{instance}': {function} was given {references} value references and {values} values"
    )]
    Lengths {
        instance: String,
        function: Function,
        references: usize,
        values: usize,
    },
    #[error("instance '{instance}': {what} is not provided by this FMU")]
    Unsupported {
        instance: String,
        what: &'static str,
    },
    /// A unit run in a worker process (isolation mode) that crashed, hung or broke the protocol.
    #[error(
        "instance '{instance}' at t = {time} s: {function} in the isolated worker process: {cause}{}",
        format_log(log)
    )]
    Isolated {
        instance: String,
        function: String,
        time: f64,
        cause: String,
        log: Vec<String>,
    },
    #[error("{path}: {message}")]
    Archive { path: PathBuf, message: String },
    #[error("{path}: modelDescription.xml: {message}")]
    Description { path: PathBuf, message: String },
    /// A modelDescription.xml that cannot be read as the standard asks (boxed: the error
    /// stays small).
    #[error("{path}: modelDescription.xml: {source}")]
    DescriptionParse {
        path: PathBuf,
        #[source]
        source: Box<DescriptionError>,
    },
}

fn format_log(lines: &[String]) -> String {
    if lines.is_empty() {
        String::new()
    } else {
        format!("; the FMU's last messages:\n  {}", lines.join("\n  "))
    }
}

impl FmuError {
    /// A refused call: the one place a status becomes an error, for every backend and both
    /// versions.
    #[cold]
    pub fn call(
        instance: &str,
        function: FmiFunction,
        status: CallStatus,
        time: f64,
        log: Vec<String>,
    ) -> FmuError {
        FmuError::Call {
            instance: instance.to_string(),
            function,
            status,
            time,
            log,
        }
    }

    /// A step that ended the simulation, as the master expects it of any instance (FMI 3.0's
    /// `terminateSimulation`, a Model Exchange FMU's): `fmi2DoStep` returning `fmi2Discard`
    /// at `time`, after which the master asks `terminated_by_fmu`.
    pub fn step_discarded(instance: &str, time: f64) -> FmuError {
        FmuError::call(
            instance,
            FmiFunction::Fmi2(Function::DoStep),
            CallStatus::Fmi2(crate::fmi2::fmi2Status::DISCARD),
            time,
            Vec::new(),
        )
    }

    /// The function of a refused call (None: another error).
    pub fn call_function(&self) -> Option<&FmiFunction> {
        match self {
            FmuError::Call { function, .. } => Some(function),
            _ => None,
        }
    }

    /// A refused `fmi2DoStep` that was discarded (FMI 2.0 §4.2.3: the FMU may end the
    /// simulation this way).
    pub fn is_discarded_fmi2_step(&self) -> bool {
        matches!(
            self,
            FmuError::Call {
                function: FmiFunction::Fmi2(Function::DoStep),
                status,
                ..
            } if status.is_discard()
        )
    }
}

/// What is wrong with a modelDescription.xml (FMI 2.0 or 3.0): the element, attribute or
/// variable, and what was found; the caller adds the file ([`FmuError::DescriptionParse`]).
#[derive(Clone, Debug, thiserror::Error)]
pub enum DescriptionError {
    #[error("XML error at byte {position}: {source}")]
    Xml {
        position: u64,
        #[source]
        source: quick_xml::Error,
    },
    #[error("bad attribute: {0}")]
    Attribute(#[source] quick_xml::events::attributes::AttrError),
    #[error("bad attribute value of '{attribute}': {source}")]
    AttributeValue {
        attribute: String,
        #[source]
        source: quick_xml::Error,
    },
    #[error(
        "the file ends before <{open}> is closed (truncated?): {depth} element{} open",
        if *depth == 1 { "" } else { "s" }
    )]
    Truncated { open: String, depth: usize },
    #[error("root element is <{found}>, expected <fmiModelDescription>")]
    Root { found: String },
    #[error("no <fmiModelDescription> element")]
    NoRoot,
    /// An element that needs a name (`<Unit>`, `<ScalarVariable>`, `<Float64>`) has none.
    #[error("<{element}> without a name")]
    Unnamed { element: String },
    #[error("<{element}> has no modelIdentifier")]
    NoModelIdentifier { element: &'static str },
    /// `context` names the element (`DefaultExperiment`, `variable 'x'`).
    #[error("{context}: attribute {attribute}=\"{found}\" is not a number")]
    NotANumber {
        context: String,
        attribute: String,
        found: String,
    },
    #[error("Enumeration '{ty}': item '{item}' has no integer value")]
    EnumerationItem { ty: String, item: String },
    #[error("unit '{unit}': <DisplayUnit> without a name")]
    UnnamedDisplayUnit { unit: String },
    #[error(
        "unit '{unit}': DisplayUnit '{name}': factor {factor} and offset {offset} do not define a unit"
    )]
    DisplayUnit {
        unit: String,
        name: String,
        factor: f64,
        offset: f64,
    },
    /// `found` is the attribute's value, shortened for the message.
    #[error(
        "<fmiModelDescription numberOfEventIndicators=\"{found}\">: expected a whole number >= 0"
    )]
    EventIndicators { found: String },
    #[error("variable '{variable}': missing or bad valueReference")]
    ValueReference { variable: String },
    #[error("variable '{variable}': {source}")]
    Schema {
        variable: String,
        #[source]
        source: crate::schema::UnknownName,
    },
    #[error("variable '{variable}' has no type element")]
    NoTypeElement { variable: String },
    #[error("ModelStructure: <Unknown> without a valid index")]
    UnknownIndex,
    /// FMI 2.0: a dependency that is no index.
    #[error("ModelStructure: bad dependency '{dependency}'")]
    Dependency { dependency: String },
    #[error("ModelStructure refers to variable index {index} of {count}")]
    Index { index: usize, count: usize },
    #[error(
        "ModelStructure: dependency index {dependency} of variable {index} is not in 1..={count}"
    )]
    DependencyIndex {
        dependency: usize,
        index: usize,
        count: usize,
    },
    /// FMI 3.0: a model structure entry (`element`: `Output`, …) without its value reference.
    #[error("ModelStructure: <{element}> without a valid valueReference")]
    EntryValueReference { element: String },
    #[error("ModelStructure: bad dependency '{dependency}' of <{element}>")]
    EntryDependency { dependency: String, element: String },
    #[error("ModelStructure: <{element} valueReference=\"{value_reference}\"> names no variable")]
    EntryNoVariable {
        element: String,
        value_reference: u32,
    },
    #[error(
        "ModelStructure: dependency {dependency} of <{element} valueReference=\"{value_reference}\"> names no variable"
    )]
    DependencyNoVariable {
        dependency: u32,
        element: String,
        value_reference: u32,
    },
    /// `rule` says what the standard allows the causality.
    #[error(
        "variable '{variable}': causality=\"{causality}\" with variability=\"{variability}\" is not allowed (FMI 2.0, section 2.2.7: {rule})"
    )]
    Combination {
        variable: String,
        causality: crate::schema::Causality,
        variability: crate::schema::Variability,
        rule: &'static str,
    },
    #[error("variable name '{name}' appears twice (value references {first} and {second})")]
    DuplicateName {
        name: String,
        first: u32,
        second: u32,
    },
    /// An FMI 2.0 alias set with more than one variable that is set; `more` when there are
    /// more than two.
    #[error(
        "value reference {value_reference} of {ty} is shared by {} '{first}' ({first_causality}) and '{second}' ({second_causality}): an alias set can have at most one variable that is set (FMI 2.0, section 2.2.7)",
        if *more { "more than" } else { "both" }
    )]
    AliasSet {
        value_reference: u32,
        ty: crate::schema::ScalarType,
        more: bool,
        first: String,
        first_causality: crate::schema::Causality,
        second: String,
        second_causality: crate::schema::Causality,
    },
    #[error(
        "value reference {value_reference} of {ty} is shared by '{first}' (start {first_start}) and '{second}' (start {second_start}): one value cannot have two start values (FMI 2.0, section 2.2.7)"
    )]
    AliasStarts {
        value_reference: u32,
        ty: crate::schema::ScalarType,
        first: String,
        first_start: String,
        second: String,
        second_start: String,
    },
    #[error("variable '{variable}': <Alias> without a name")]
    UnnamedAlias { variable: String },
    #[error(
        "ModelVariables: <{element}> is not an FMI 3.0 variable element (Float64, Int32, Boolean, String, …; an FMI 2.0 description under fmiVersion=\"3.0\"?)"
    )]
    NotAVariable { element: String },
    #[error("variable '{variable}': a <Dimension> has start or valueReference, not both")]
    DimensionBoth { variable: String },
    #[error("variable '{variable}': Dimension start=\"{found}\" is not a size")]
    DimensionStart { variable: String, found: String },
    #[error(
        "variable '{variable}': Dimension valueReference=\"{found}\" is not a value reference"
    )]
    DimensionValueReference { variable: String, found: String },
    #[error("variable '{variable}': <Dimension> has neither start nor valueReference")]
    DimensionNeither { variable: String },
    #[error(
        "variable '{variable}': a Dimension refers to value reference {value_reference}, which is no structural parameter"
    )]
    DimensionNotStructural {
        variable: String,
        value_reference: u32,
    },
    #[error(
        "variable '{variable}': its dimension '{parameter}' has no start value that is a size"
    )]
    DimensionNoStart { variable: String, parameter: String },
    #[error(
        "value reference {value_reference} is declared twice, for '{first}' and '{second}' (FMI 3.0 gives every variable its own; another name of one variable is an <Alias>)"
    )]
    DuplicateValueReference {
        value_reference: u32,
        first: String,
        second: String,
    },
    #[error(
        "variable '{variable}': the arrays so far hold more than {limit} values in all (elements and their aliases): more than twinbench expands into columns"
    )]
    TooManyValues { variable: String, limit: u64 },
    #[error("variable '{variable}': an array of dimensions {sizes:?}, more than {limit} elements")]
    ArrayTooLarge {
        variable: String,
        sizes: Vec<u64>,
        limit: u64,
    },
    #[error("variable '{variable}': {starts} start values for an array of {elements} elements")]
    StartValues {
        variable: String,
        starts: usize,
        elements: u64,
    },
    #[error("variable '{variable}': no value reference left for its elements")]
    NoValueReferenceLeft { variable: String },
}

/// Why an unpacked file cannot be trusted or is not the one unpacked: the path checked and
/// what was found there.
#[derive(Debug, thiserror::Error)]
pub enum FileCheckError {
    /// A check of a path outside any folder.
    #[error("no folder")]
    NoFolder,
    #[error("{path}: the path holds a NUL byte")]
    NulByte { path: PathBuf },
    #[error("{path}: cannot open: {source}")]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: it belongs to user id {owner}, not to this user ({me})")]
    Owner { path: PathBuf, owner: u32, me: u32 },
    #[error("{path}: mode {mode:o}: group or others can write it")]
    Writable { path: PathBuf, mode: u32 },
    #[error("{path}: is a symbolic link")]
    Link { path: PathBuf },
    #[error("{path}: not a regular file")]
    NotRegular { path: PathBuf },
    /// An empty relative path: the walk ended without a file.
    #[error("{path}: no file named")]
    NoFileNamed { path: PathBuf },
    #[error("{path}: mode {found:o}, the unpacking set {expected:o}")]
    Mode {
        path: PathBuf,
        found: u32,
        expected: u32,
    },
    #[error("{path}: {found} bytes, {expected} when unpacked")]
    Size {
        path: PathBuf,
        found: u64,
        expected: u64,
    },
    #[error(
        "{path}: its content is not the unpacked one (BLAKE3 {found}, {expected} when unpacked)"
    )]
    Content {
        path: PathBuf,
        found: String,
        expected: String,
    },
}

/// Why an unpacked folder cannot be used for its archive (it is unpacked again).
#[derive(Debug, thiserror::Error)]
pub enum FolderError {
    #[error(transparent)]
    File(#[from] FileCheckError),
    #[error("its manifest: {0}")]
    ManifestRead(#[source] std::io::Error),
    #[error("its manifest is damaged")]
    ManifestDamaged,
    #[error("its manifest is of another archive")]
    OtherArchive,
    #[error("its manifest does not list the archive's files")]
    OtherFiles,
    #[error("no modelDescription.xml")]
    NoDescription,
    #[error(
        "{path}: {size} bytes, mode {mode:o}; unpacked: {unpacked_size} bytes, mode {unpacked_mode:o}"
    )]
    DescriptionChanged {
        path: PathBuf,
        size: u64,
        mode: u32,
        unpacked_size: u64,
        unpacked_mode: u32,
    },
    #[error("modelDescription.xml: {0}")]
    DescriptionRead(#[source] std::io::Error),
    #[error("{path}: its content is not the unpacked one")]
    DescriptionContent { path: PathBuf },
}

/// Why an FMU cannot run through an interface.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum InterfaceError {
    /// `element`: the interface's element (`CoSimulation`); `supported`: the names of the
    /// interfaces the FMU has.
    #[error(
        "the FMU has no <{element}> element (it supports {} only)",
        supported.join(" and ")
    )]
    NotDeclared {
        element: &'static str,
        supported: Vec<&'static str>,
    },
    #[error("no {entry}, the {element} library (the FMU has no binary of it for this platform)")]
    NoBinary {
        entry: String,
        element: &'static str,
    },
}
