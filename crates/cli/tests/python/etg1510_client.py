"""pyetg1510 (PyPI, unmodified) against ferrocat's mailbox gateway: the master's object
dictionary by SDO information, then every object, printed as one JSON line.

    etg1510_client.py HOST PORT
"""
import asyncio
import json
import sys
from dataclasses import fields

from pyetg1510 import EtherCATMasterConnection, MasterODSpecification, ETG1510Profile, SysLog, LoggingLevel


async def main(host, port):
    spec = MasterODSpecification(connection=EtherCATMasterConnection(host, port))
    await spec.get_object_dictionary()
    profile = ETG1510Profile(master_od=spec)
    objects = {}
    async for index, data in profile:
        objects[f"{index:#06x}"] = {f.name: getattr(data, f.name).value for f in fields(data)}
    diag = {}
    for index in sorted(i for i in profile.sdo_database if 0xA000 <= i <= 0xAFFF):
        d = await profile.get_sdo(index)
        try:
            al_status = d.al_status.name
        except ValueError:
            # 0: the slave did not answer the live read (pyetg1510's enum has no 0).
            al_status = None
        diag[f"{index:#06x}"] = {
            "al_status": al_status,
            "al_status_code": d.ALStatusCode.value,
            "ports": [[p.use_to_communication, p.link_up] for p in d.port_status],
        }
    print(json.dumps({"indices": sorted(objects), "objects": objects, "diagnosis": diag}, default=str))


if __name__ == "__main__":
    SysLog.console_log_configuration(LoggingLevel.DISABLE)
    SysLog.syslog_configuration(LoggingLevel.DISABLE)
    SysLog.rotation_log_configuration(LoggingLevel.DISABLE)
    SysLog.set_loglevel(LoggingLevel.ERROR)
    asyncio.run(main(sys.argv[1], int(sys.argv[2])))
