//! The CoE object dictionary of an ESI `<Profile><Dictionary>`: data types and objects, with
//! record and array types expanded into their subindices.

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Access {
    pub read: bool,
    pub write: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DataTypeSubItem {
    pub subindex: Option<u8>,
    pub name: String,
    pub type_name: String,
    pub bit_size: u32,
    pub bit_offset: u32,
    pub access: Option<Access>,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DataType {
    pub name: String,
    pub base_type: Option<String>,
    pub bit_size: u32,
    /// Lower bound and element count of an array type.
    pub array: Option<(u32, u32)>,
    pub subitems: Vec<DataTypeSubItem>,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SubObject {
    pub subindex: u8,
    pub name: String,
    pub type_name: String,
    pub bit_size: u32,
    pub bit_offset: u32,
    pub access: Access,
    /// Default value as bytes in CoE (little-endian) order.
    pub default_data: Option<Vec<u8>>,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Object {
    pub index: u16,
    /// Whether the index moves with the slot, in a module's dictionary.
    pub index_depends: crate::Depend,
    pub name: String,
    pub type_name: String,
    pub bit_size: u32,
    pub access: Access,
    /// `T`, `R`, `TR`, … where the object may be mapped into PDOs.
    pub pdo_mapping: Option<String>,
    pub default_data: Option<Vec<u8>>,
    /// Subindices of a record or array (empty for a simple variable).
    pub subs: Vec<SubObject>,
    /// The object's type lays its entries out as an array (else a record).
    pub is_array: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Dictionary {
    pub data_types: Vec<DataType>,
    pub objects: Vec<Object>,
}

impl Dictionary {
    pub fn data_type(&self, name: &str) -> Option<&DataType> {
        self.data_types.iter().find(|t| t.name == name)
    }
    pub fn object(&self, index: u16) -> Option<&Object> {
        self.objects.iter().find(|o| o.index == index)
    }
}
