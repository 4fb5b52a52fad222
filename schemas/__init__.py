"""ROS 2 message types <-> Avro.

Load standard and custom ROS 2 type definitions (``typestore``), compute their RIHS01 type
hashes (``typehash``), derive Avro schemas from them (``avro_schema``), convert CDR payloads to
Avro and back (``codec``), frame Avro bodies (``single_object``) and talk to a schema registry
(``registry``). Import the submodules directly; this package import stays cheap.
"""
